"""The surface-guided marcher (texvocab.render.guided): its closed-form VolSDF
quadrature, its agreement with the shell marcher on the body's own SDF, what it costs,
and the extremes (camera inside the body, rays that miss, a one-point field call)."""

import numpy as np
import pytest
import torch
from render_cases import GUIDED, SHELL, looking_away, psnr

from texvocab.capture.camera import Camera
from texvocab.render import render_image
from texvocab.render.volume.volsdf import composite_linear_sdf, interval_optical_depth


def density(s: torch.Tensor, beta: float) -> torch.Tensor:
    return torch.where(s >= 0, 0.5 * torch.exp(-s / beta), 1 - 0.5 * torch.exp(s / beta)) / beta


@pytest.mark.parametrize(
    "s_a,s_b", [(0.01, -0.01), (0.004, 0.001), (-0.002, -0.02), (0.003, 0.003), (-0.005, 0.006)]
)
def test_interval_optical_depth_is_the_integral_of_a_linear_sdf(s_a, s_b):
    beta, length = 0.002, 0.013
    x = (torch.arange(200_000, dtype=torch.float64) + 0.5) / 200_000
    riemann = density(s_a + (s_b - s_a) * x, beta).mean() * length
    got = interval_optical_depth(
        torch.tensor([s_a], dtype=torch.float64),
        torch.tensor([s_b], dtype=torch.float64),
        torch.tensor([length], dtype=torch.float64),
        beta,
    )
    assert float(got) == pytest.approx(float(riemann), rel=1e-6)


def test_interval_optical_depth_has_finite_gradients_far_from_the_surface():
    """Samples metres outside or inside the surface (SDF / β ~ ±500, where e^(SDF/β)
    overflows float32) give finite values and gradients w.r.t. the SDF and β, on flat
    (s_a = s_b) and sloped intervals alike."""
    beta = torch.tensor(0.002, requires_grad=True)
    s_a = torch.tensor([1.0, -1.0, 1.0, -1.0, 0.5], requires_grad=True)
    s_b = torch.tensor([1.0, -1.0, 0.9, -0.9, -0.5], requires_grad=True)
    tau = interval_optical_depth(s_a, s_b, torch.full((5,), 0.01), beta)
    tau.sum().backward()
    assert torch.isfinite(tau).all() and float(tau[0]) == 0.0 and float(tau[1]) > 4
    for g in (beta.grad, s_a.grad, s_b.grad):
        assert torch.isfinite(g).all()


def test_closed_form_compositing_matches_dense_sampling_of_a_plane():
    """A ray crossing a plane at 60°: 5 samples in closed form vs 20k midpoint samples."""
    beta, c = 0.003, 0.5
    t = torch.tensor([[0.99, 0.995, 1.0, 1.005, 1.01]], dtype=torch.float64)
    sdf = -c * (t - 1.0)
    rgb = torch.stack([t[0] * 0 + 0.2, (t[0] - 0.99) * 30, t[0] * 0 + 0.7], -1)[None]
    acc, color, depth, rest = composite_linear_sdf(t, sdf, rgb, beta)
    u = torch.linspace(0.5, 1.1, 20_001, dtype=torch.float64)
    du = u[1] - u[0]
    tau = density(-c * (u - 1.0), beta) * du
    w = torch.exp(-(torch.cumsum(tau, 0) - tau)) * -torch.expm1(-tau)
    col = torch.stack([u * 0 + 0.2, ((u - 0.99) * 30).clamp(0, 0.6), u * 0 + 0.7], -1)
    ref = (w[:, None] * col).sum(0)
    assert float(acc) == pytest.approx(1.0) and float(rest) < 0.06
    assert torch.allclose(color[0], ref, atol=0.02)
    assert float(depth) == pytest.approx(float((w * u).sum()), abs=2e-3)


def test_guided_matches_the_shell_marcher_with_fewer_evaluations(body):
    v, f, cam, field = body["v"], body["f"], body["camera"], body["field"]
    with torch.no_grad():
        shell = render_image(field, cam, v, f, SHELL, shell=body["shell"])
        guided = render_image(field, cam, v, f, GUIDED, shell=body["shell"])
    assert psnr(guided.rgb, shell.rgb) > 40
    assert (guided.alpha - shell.alpha).abs().max() < 0.1
    paths = guided.stats.paths
    assert paths["band"] > paths["residual"] > 0 and paths["background"] > 0
    kind = guided.stats.kind
    for code, path in ((2, "band"), (3, "fallback"), (4, "residual")):
        assert int((kind == code).sum()) == paths[path]
    assert guided.stats.field_evals < 0.5 * shell.stats.field_evals
    # the band path's rays hold the surface colour the shell marcher finds
    band = kind == 2
    assert (guided.rgb[band] - shell.rgb[band]).abs().max() < 0.05


def test_guided_rays_that_miss_everything_cost_nothing(body):
    bg = (0.2, 0.4, 0.6)
    result = render_image(
        body["field"], looking_away(body["camera"]), body["v"], body["f"], GUIDED, background=bg
    )
    assert result.stats.field_evals == 0
    assert torch.equal(result.rgb, torch.tensor(bg).expand(64, 64, 3))


@pytest.mark.parametrize("where", ["inside", "surface_in"])
def test_guided_camera_inside_the_body_is_finite(body, where):
    v, f = body["v"], body["f"]
    if where == "inside":
        centre, R = body["joints"][0].double().numpy(), np.eye(3)
    else:
        chest = body["joints"][9]
        near_axis = ((v[:, :2] - chest[:2]).norm(dim=1) < 0.05).float()
        centre = v[int((v[:, 2] * near_axis - 9 * (1 - near_axis)).argmax())].double().numpy()
        R = np.diag([-1.0, 1.0, -1.0])
    K = np.array([[20.0, 0, 11.5], [0, 20.0, 11.5], [0, 0, 1]])
    cam = Camera(K, R, -R @ centre, 24, 24)
    result = render_image(body["field"], cam, v, f, GUIDED, shell=body["shell"])
    for x in (result.rgb, result.alpha, result.depth):
        assert torch.isfinite(x).all()
    assert (result.alpha >= 0).all() and (result.alpha <= 1 + 1e-6).all()
    assert (result.rgb >= 0).all() and (result.rgb <= 1 + 1e-6).all()
    # the viewer's progressive levels (preview first, the shell built on demand) too
    from texvocab.render import progressive_render

    levels = list(progressive_render(body["field"], cam, v, f, GUIDED, shell=lambda: body["shell"]))
    assert [lv for lv, _, _ in levels] == [8, 4, 2, 1]
    assert torch.allclose(levels[-1][1], result.rgb, atol=1e-5)
    assert all(torch.isfinite(img).all() for _, img, _ in levels)


def test_guided_progressive_levels_of_rays_that_all_miss(body):
    from texvocab.render import progressive_render

    bg = (0.2, 0.4, 0.6)
    levels = list(
        progressive_render(
            body["field"], looking_away(body["camera"]), body["v"], body["f"], GUIDED, background=bg
        )
    )
    assert [lv for lv, _, _ in levels] == [8, 4, 2, 1]
    assert torch.equal(levels[-1][1], torch.tensor(bg).expand(64, 64, 3))


def test_unknown_guide_is_refused(body):
    with pytest.raises(ValueError, match="guide"):
        render_image(body["field"], body["camera"], body["v"], body["f"], SHELL.replace(guide="mesh"))


def test_guide_is_a_render_knob_that_training_never_uses():
    from texvocab.errors import TexvocabError
    from texvocab.pipeline.settings import RenderSettings, Settings, march_settings, render_overrides

    s = Settings()
    assert march_settings(s).guide == "raster" and march_settings(s, training=True).guide == "shell"
    assert march_settings(render_overrides(s, None, ["guide=shell"])).guide == "shell"
    assert march_settings(render_overrides(s, "fast", [])).guide == "raster"
    with pytest.raises(TexvocabError, match="render.guide"):
        RenderSettings(guide="mesh")


def test_a_one_point_field_call_works(body):
    """The guided marcher and the viewer's smallest levels call the field with single
    points (the viewer used to pad such calls)."""
    field = body["field"]
    sigma, rgb = field(body["v"][:1], torch.tensor([[0.0, 0.0, 1.0]]))
    sdf, rgb2 = field.sdf_rgb(body["v"][:1], torch.tensor([[0.0, 0.0, 1.0]]))
    assert sigma.shape == (1,) and rgb.shape == (1, 3) and sdf.shape == (1,)
    assert torch.equal(rgb, rgb2)


@pytest.mark.parametrize(
    "knob,value",
    [
        ("band_samples", 6),
        ("band_spacing", 3.0),
        ("min_cos", 0.6),
        ("miss_margin", 6.0),
        ("band_leftover", 1e-6),
        ("fallback_segment", 8),
        ("fallback_scout", None),
        ("fallback_grid_rays", 100_000),
        ("residual_rays", False),
        ("residual_tolerance", 0.1),
        ("band_newton", False),
    ],
)
def test_every_guided_knob_changes_the_render(body, knob, value):
    """Each documented knob of the guided marcher changes what it evaluates (the ones
    that only act on the 4-sample band or on marched rays, with those in use)."""
    v, f, cam, field = body["v"], body["f"], body["camera"], body["field"]
    marched = {"band_samples", "fallback_segment", "fallback_scout", "fallback_grid_rays"}
    start = GUIDED.replace(band_newton=False, residual_rays=False) if knob in marched else GUIDED
    with torch.no_grad():
        base = render_image(field, cam, v, f, start, shell=body["shell"])
        other = render_image(field, cam, v, f, start.replace(**{knob: value}), shell=body["shell"])
    assert (other.stats.field_evals, other.stats.paths) != (base.stats.field_evals, base.stats.paths)
    assert psnr(other.rgb, base.rgb) > 35  # a trade, not a different image


def test_guided_progressive_levels_render_each_pixel_once(body):
    """Levels are the full image's pixel grids [::L, ::L]; after the preview they cost
    one full render together (same field evaluations) and the last level is that render.
    The preview (its own camera of every 8th pixel, fallback rays at their probe's
    colour) differs at few pixels."""
    from texvocab.render import progressive_render
    from texvocab.render.guided import GuidedImage

    v, f, cam, field = body["v"], body["f"], body["camera"], body["field"]
    with torch.no_grad():
        full = render_image(field, cam, v, f, GUIDED, shell=body["shell"])
        parts = GuidedImage(field, cam, v, f, GUIDED, shell=body["shell"])
        coarse = torch.zeros(cam.height, cam.width, dtype=torch.bool)
        coarse[::4, ::4] = True
        parts.render(coarse)
        after_coarse = parts.evals
        parts.render(~coarse)
    assert 0 < after_coarse < parts.evals
    assert parts.evals == full.stats.field_evals  # no ray twice
    assert torch.allclose(parts.result().rgb, full.rgb, atol=1e-5)
    levels = list(progressive_render(field, cam, v, f, GUIDED, shell=body["shell"]))
    assert [lv for lv, _, _ in levels] == [8, 4, 2, 1]
    last = levels[-1][1]
    assert torch.allclose(last, full.rgb, atol=1e-5)
    for lv, img, _ in levels:
        assert img.shape == (-(-cam.height // lv), -(-cam.width // lv), 3)
        if lv < 8:
            assert torch.allclose(img, last[::lv, ::lv], atol=1e-5)
    off = (levels[0][1] - last[::8, ::8]).abs().max(-1).values > 1e-3
    assert off.float().mean() <= 0.05


def test_level_owners_split_each_level_once_and_give_the_preview_to_shard_0():
    from texvocab.render import level_owners

    h, w, levels = 37, 29, (8, 4, 2, 1)
    seen = torch.zeros(h, w, dtype=torch.bool)
    for i, (level, owner) in enumerate(zip(levels, level_owners(h, w, levels, 3))):
        grid = torch.zeros(h, w, dtype=torch.bool)
        grid[::level, ::level] = True
        new = owner >= 0
        counts = torch.bincount(owner[new].long(), minlength=3)
        if i == 0:  # the preview is shard 0's, and its pixels are rendered again
            assert torch.equal(new, grid) and counts.tolist() == [int(new.sum()), 0, 0]
            continue
        assert torch.equal(new, grid & ~seen), level  # each pixel once, at its first level
        assert counts.max() - counts.min() <= 1  # balanced
        seen |= grid
    assert seen.all()
    # one level alone (a playback render) is split too
    (owner,) = level_owners(h, w, (4,), 2)
    assert set(torch.unique(owner).tolist()) == {-1, 0, 1}


@pytest.mark.parametrize("guide", ["raster", "shell"])
def test_shards_together_render_the_image_of_one_render(body, guide):
    """Two shards of a view (the viewer's two render processes), merged by their owned
    pixels, give the progressive render's levels."""
    from texvocab.render import progressive_render, progressive_shard

    s = SHELL.replace(guide=guide)
    args = (body["field"], body["camera"], body["v"], body["f"], s)
    whole = list(progressive_render(*args, shell=body["shell"]))
    shards = [list(progressive_shard(*args, shell=body["shell"], shard=(k, 2))) for k in range(2)]
    for i, (level, image, _) in enumerate(whole):
        merged = torch.zeros_like(image)
        owned_by = torch.zeros(image.shape[:2], dtype=torch.int64)
        for k in range(2):
            lv, img, _, owned = shards[k][i]
            assert lv == level and img.shape == image.shape
            merged[owned] = img[owned]
            owned_by += owned.long()
        assert (owned_by == 1).all(), level  # every pixel of the level from one shard
        assert torch.allclose(merged, image, atol=1e-5), level
        if guide == "raster" and level < 8:  # later levels are split
            assert 0 < int(shards[1][i][3].sum()) < owned_by.numel()
    assert not shards[1][0][3].any()  # the preview is shard 0's
