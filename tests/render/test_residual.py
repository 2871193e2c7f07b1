"""Residual rays and the Newton band (texvocab.render.guided.residual, .band): the mesh's
distance plus the field's residual from a few evaluations, against a dense march of the same
field."""

import pytest
import torch
from render_cases import GUIDED, SHELL, psnr

from texvocab.render import render_image
from texvocab.render.analytic import MeshResidualField
from texvocab.render.guided.residual import _part_that_matters
from texvocab.render.volume.volsdf import composite_linear_sdf

DENSE = SHELL.replace(coarse_samples=96, fine_samples=48, early_stop_eps=0.0)
MARCHED = GUIDED.replace(residual_rays=False, band_newton=False)


def count_mesh_queries(monkeypatch) -> dict:
    """{"points": n}, n counting the points the residual rays' mesh queries take from now."""
    import texvocab.render.guided.residual as residual

    queried = {"points": 0}
    faces_of = residual.mesh_distance_faces

    def counted(index, points, cap, known=None):
        queried["points"] += len(points)
        return faces_of(index, points, cap, known)

    monkeypatch.setattr(residual, "mesh_distance_faces", counted)
    return queried


def renders(body, field, *settings):
    with torch.no_grad():
        return [
            render_image(field, body["camera"], body["v"], body["f"], s, shell=body["shell"])
            for s in settings
        ]


def test_smooth_residual_rays_match_a_dense_march_with_few_evaluations(body):
    """A residual of 2 mm varying over 30 cm (the avatar's kind): the silhouette
    fringe, grazing hits and occlusion edges take 3 evaluations each instead of a
    march, the band 3 instead of 5, and the image stays within 50 dB of a dense march."""
    field = MeshResidualField(body["v"], body["f"], beta=0.003, amplitude=0.002, wavenumber=20.0)
    dense, guided, marched = renders(body, field, DENSE, GUIDED, MARCHED)
    paths = guided.stats.paths
    assert paths["residual"] > 100 and paths["fallback"] <= 5
    assert guided.stats.field_evals < 0.25 * marched.stats.field_evals
    assert psnr(guided.rgb, dense.rgb) > 50
    fringe = guided.stats.kind == 4
    err = (guided.alpha - dense.alpha).abs()[fringe]
    assert float(err.mean()) < 0.005 and float(err.max()) < 0.1
    band = guided.stats.kind == 2
    assert float((guided.rgb - dense.rgb).abs()[band].max()) < 0.05


def test_a_longer_step_trades_mesh_queries_for_little_accuracy(body, monkeypatch):
    """Mesh samples every 3 β (``render.residual_step=3``) instead of 1.5 β: at least a
    fifth fewer mesh queries on this field, and the image as close to a dense march (50 dB),
    its fringe's opacity within 1 % on average."""
    queried = count_mesh_queries(monkeypatch)
    field = MeshResidualField(body["v"], body["f"], beta=0.003, amplitude=0.002, wavenumber=20.0)
    (dense,) = renders(body, field, DENSE)
    counts, images = [], []
    for settings in (GUIDED.replace(residual_step=3.0), GUIDED):
        queried["points"] = 0
        images.append(renders(body, field, settings)[0])
        counts.append(queried["points"])
    coarse, fine = images
    assert GUIDED.residual.step == 1.5 and counts[0] < 0.8 * counts[1]
    assert coarse.stats.paths["residual"] > 100 and psnr(coarse.rgb, dense.rgb) > 50
    fringe = coarse.stats.kind == 4
    assert float((coarse.alpha - dense.alpha).abs()[fringe].mean()) < 0.01
    assert abs(psnr(coarse.rgb, dense.rgb) - psnr(fine.rgb, dense.rgb)) < 2.0


def test_rough_residual_rays_are_marched(body):
    """A residual of 1 cm varying over 3 cm breaks the slowly-varying premise: the
    residuals at the evaluations disagree by more than ``residual_tolerance`` β on most
    rays, which are then marched, so the image stays as close to the dense march as the
    marched path's."""
    field = MeshResidualField(body["v"], body["f"], beta=0.003, amplitude=0.01, wavenumber=200.0)
    dense, guided, marched = renders(body, field, DENSE, GUIDED, MARCHED)
    paths = guided.stats.paths
    assert paths["fallback"] > 5 * (paths["residual"] + paths["band"])
    assert psnr(guided.rgb, dense.rgb) > psnr(marched.rgb, dense.rgb) - 1.0


def test_residual_step_changes_the_quadrature(body):
    field = MeshResidualField(body["v"], body["f"], beta=0.003)
    base, fine = renders(body, field, GUIDED, GUIDED.replace(residual_step=0.5))
    assert not torch.equal(base.rgb, fine.rgb) and psnr(base.rgb, fine.rgb) > 45


def test_residual_spread_moves_the_evaluations(body):
    field = MeshResidualField(body["v"], body["f"], beta=0.003)
    base, wide = renders(body, field, GUIDED, GUIDED.replace(residual_spread=0.3))
    assert not torch.equal(base.rgb, wide.rgb) and psnr(base.rgb, wide.rgb) > 40


def test_the_part_that_matters_holds_every_low_point():
    """On random 1-Lipschitz profiles sampled every `step`: every point of the fine
    profile within _KEEP β of max(least, 0) lies in the part, up to the opaque cut."""
    from texvocab.render.guided.residual import _KEEP

    g = torch.Generator().manual_seed(0)
    beta, fine = 0.002, 64  # coarse samples every 8 mm (fine = 64 profile points apart)
    x = torch.linspace(0, 0.4, 50 * fine + 1, dtype=torch.float64)
    for _ in range(20):
        slopes = torch.rand(len(x) - 1, generator=g, dtype=torch.float64) * 2 - 1
        s = 0.004 + torch.cat([torch.zeros(1, dtype=torch.float64), torch.cumsum(slopes * (x[1] - x[0]), 0)])
        s = s.clamp(min=0.01)  # passes 5 β away at least: never opaque (no cut)
        t, sc = x[::fine][None], s[::fine][None]
        _, first, end, found = _part_that_matters(t, sc, torch.ones_like(t, dtype=torch.bool), beta)
        low = x[s <= s.min().clamp(min=0) + _KEEP * beta]
        assert bool(found[0])
        assert float(t[0, first[0]]) <= float(low.min()) + 1e-12
        assert float(t[0, end[0]]) >= float(low.max()) - 1e-12


def test_composite_without_the_front_part_ignores_a_flat_first_interval():
    """A ray whose samples start on a flat stretch (e.g. capped at the shell width):
    extrapolating in front of the first sample would put density there."""
    beta = 0.003
    t = torch.tensor([[0.0, 0.01, 0.02, 0.025, 0.03]], dtype=torch.float64)
    sdf = torch.tensor([[0.025, 0.025, 0.006, 0.003, 0.004]], dtype=torch.float64)
    rgb = torch.ones(1, 5, 3, dtype=torch.float64)
    with_front = composite_linear_sdf(t, sdf, rgb, beta)[0]
    without = composite_linear_sdf(t, sdf, rgb, beta, front=False)[0]
    assert float(with_front) > float(without) + 0.05
    assert 0 < float(without) < 0.5


@pytest.mark.parametrize("where", ["behind", "grazing"])
def test_residual_rays_stay_finite_from_inside_and_at_grazing_views(body, where):
    """Rays that start inside the body or graze it along a limb: finite, in range."""
    import numpy as np

    from texvocab.capture.camera import Camera

    v = body["v"]
    field = MeshResidualField(v, body["f"], beta=0.003)
    if where == "behind":
        centre, R = body["joints"][0].double().numpy(), np.eye(3)
    else:  # down the length of the body, from above the head
        top = v[int(v[:, 1].argmax())].double().numpy()
        centre = top + np.array([0.0, 0.3, 0.0])
        R = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
    K = np.array([[20.0, 0, 11.5], [0, 20.0, 11.5], [0, 0, 1]])
    cam = Camera(K, R, -R @ centre, 24, 24)
    with torch.no_grad():
        out = render_image(field, cam, v, body["f"], GUIDED, shell=body["shell"])
    for x in (out.rgb, out.alpha, out.depth):
        assert torch.isfinite(x).all()
    assert (out.alpha >= 0).all() and (out.alpha <= 1 + 1e-6).all()
    assert (out.rgb >= 0).all() and (out.rgb <= 1 + 1e-6).all()


def test_coarser_passes_narrow_the_residual_rays_to_the_same_image(body, monkeypatch):
    """At a trained avatar's β (0.5 mm) the dense steps are 0.75 mm and a ray through
    the body crosses 20-30 cm of shell: passes at 16 and 64 ``residual_step`` β keep only
    the part around where the ray enters, so the residual rays query the mesh far less
    often and render the image of the pass over the whole interval."""
    queried = count_mesh_queries(monkeypatch)
    field = MeshResidualField(body["v"], body["f"], beta=0.0005, amplitude=0.0002, wavenumber=20.0)
    camera = body["camera"].scaled(2.0)  # 128²: the residual rays are a pixel's fringe
    images, counts = [], []
    for levels in (0, 2):
        queried["points"] = 0
        with torch.no_grad():
            image = render_image(field, camera, body["v"], body["f"], GUIDED.replace(residual_levels=levels))
        images.append(image)
        counts.append(queried["points"])
    whole, narrowed = images
    assert narrowed.stats.paths["residual"] > 50
    assert (narrowed.stats.kind != whole.stats.kind).float().mean() <= 0.002
    assert psnr(narrowed.rgb, whole.rgb) > 60 and float((narrowed.alpha - whole.alpha).abs().max()) < 0.01
    assert counts[1] < 0.7 * counts[0]


def test_marching_without_the_grid_gives_the_grid_marchs_image(body):
    """``fallback_grid_rays``: a few marched rays march their whole shell interval instead
    of building the occupancy grid; the image is the grid march's, as close to a dense
    march, with more field evaluations for the empty stretches."""
    field = MeshResidualField(body["v"], body["f"], beta=0.003, amplitude=0.01, wavenumber=200.0)
    grid, gridless = GUIDED.replace(fallback_grid_rays=0), GUIDED.replace(fallback_grid_rays=100_000)
    with torch.no_grad():
        images = [
            render_image(field, body["camera"], body["v"], body["f"], s) for s in (DENSE, grid, gridless)
        ]
    dense, on_grid, off_grid = images
    assert on_grid.stats.paths["fallback"] > 100
    assert off_grid.stats.field_evals > on_grid.stats.field_evals
    assert psnr(off_grid.rgb, on_grid.rgb) > 40
    assert psnr(off_grid.rgb, dense.rgb) > psnr(on_grid.rgb, dense.rgb) - 1.0


@pytest.mark.parametrize("knobs", [{}, {"residual_levels": 0}, {"residual_retries": 1, "residual_step": 3.0}])
def test_compiled_mesh_samples_are_the_padded_references(body, monkeypatch, knobs):
    """The residual rays' mesh samples placed ray by ray (compiled, no padding) are the
    torch reference's, bit for bit (samples, distances, faces, counts, found), on every
    call a frame makes; so is the image."""
    import texvocab.render.guided.residual as residual

    calls = []

    def both(*args):
        ours, ref = residual.compiled_mesh_samples(*args), residual.padded_mesh_samples(*args)
        calls.append(len(ours[3]))
        for a, b in zip(ours, ref, strict=True):
            assert a.dtype == b.dtype and a.shape == b.shape and torch.equal(a, b)
        return ours

    field = MeshResidualField(body["v"], body["f"], beta=0.0008, amplitude=0.001, wavenumber=20.0)
    settings, camera = GUIDED.replace(**knobs), body["camera"].scaled(2.0)
    monkeypatch.setattr(residual, "mesh_samples", both)
    with torch.no_grad():
        checked = render_image(field, camera, body["v"], body["f"], settings)
    assert calls and sum(calls) > 50
    monkeypatch.setattr(residual, "mesh_samples", residual.padded_mesh_samples)
    with torch.no_grad():
        padded = render_image(field, camera, body["v"], body["f"], settings)
    assert torch.equal(checked.rgb, padded.rgb) and torch.equal(checked.stats.kind, padded.stats.kind)


@pytest.mark.parametrize(
    "knobs, beta, amplitude",
    [
        ({}, 0.0008, 0.002),
        ({"residual_retries": 1, "residual_step": 3.0}, 0.0008, 0.002),
        # a soft, offset surface: samples beyond the shell still carry weight
        ({"residual_levels": 0}, 0.005, 0.006),
    ],
)
def test_compiled_quadrature_is_the_torch_groups(body, monkeypatch, knobs, beta, amplitude):
    """At render time (β a float) the residual rays' quadrature runs compiled, ray by ray:
    the knots, their SDFs and faces, and each ray's opacity, colour, depth and ok are
    torch's groups of padded arrays (the differentiable path training takes, with the
    model's β) to float rounding, on every call a frame makes, retries included (and
    samples beyond the shell, which read the shell width in float32); so is the image."""
    import texvocab.render.guided.residual as residual

    calls, compiled = [], residual.compiled_quadrature

    def both(field, origin, dirs, *rest):
        ours = compiled(field, origin, dirs, *rest)
        ref = residual.grouped_quadrature(field, origin, dirs, *rest)
        calls.append(len(dirs))
        (k1, f1, s1, out1), (k2, f2, s2, out2) = ours, ref
        assert torch.equal(k1, k2) and torch.equal(f1, f2)
        assert torch.allclose(s1, s2, atol=1e-6)
        for a, b in zip(out1[:3], out2[:3], strict=True):
            assert a.dtype == b.dtype and a.shape == b.shape and torch.allclose(a, b, atol=1e-4)
        assert float((out1[3] != out2[3]).float().mean()) <= 0.01
        return ours

    field = MeshResidualField(body["v"], body["f"], beta=beta, amplitude=amplitude, wavenumber=20.0)
    settings, camera = GUIDED.replace(**knobs), body["camera"].scaled(2.0)
    monkeypatch.setattr(residual, "compiled_quadrature", both)
    with torch.no_grad():
        checked = render_image(field, camera, body["v"], body["f"], settings)
    assert calls and sum(calls) > 50
    monkeypatch.setattr(residual, "quadrature_compiled", False)
    with torch.no_grad():
        grouped = render_image(field, camera, body["v"], body["f"], settings)
    assert checked.stats.paths["residual"] > 50
    assert psnr(checked.rgb, grouped.rgb) > 80
    assert (checked.stats.kind != grouped.stats.kind).float().mean() <= 0.001
