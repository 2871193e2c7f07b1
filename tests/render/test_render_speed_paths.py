"""Faster exact paths of the neural render give the same field values, gradients and
images as the computation they replace (the weights keep their meaning)."""

import numpy as np
import pytest
import torch

from texvocab.body import default_body
from texvocab.body.poses import preset
from texvocab.capture.synth import SynthSettings, default_cameras
from texvocab.geometry.rotations import rotvec_to_quat
from texvocab.method.encoder import build_encoder
from texvocab.method.feature import PoseFeature
from texvocab.method.field import AvatarField, FieldSettings, NormalSoftplus
from texvocab.method.vocab import Vocabulary
from texvocab.render import MarchSettings, ShellGeometry, render_image


def _concat_hidden(field, ctx, x):
    """The original first layer: sdf_net on [x, q(Θ) repeated per point]."""
    pose = rotvec_to_quat(ctx.pose.to(x.dtype)).reshape(1, -1).expand(len(x), -1)
    return field.sdf_net(torch.cat([x, pose], -1))


@pytest.fixture(scope="module")
def field():
    body = default_body()
    vocab = Vocabulary.build(np.random.default_rng(0).normal(0, 0.2, (4, 24, 3)), num_keys=4, k=2)
    textures = torch.rand(4, 3, 32, 32, generator=torch.Generator().manual_seed(1))
    with torch.random.fork_rng():  # the layers' default init draws from the global stream:
        torch.manual_seed(0)  # seeded, so the weights do not depend on the tests run before
        pf = PoseFeature(body, vocab, textures, build_encoder("small"))
        f = AvatarField(pf, FieldSettings(hidden=32))
    gen = torch.Generator().manual_seed(2)
    with torch.no_grad():  # a "trained" residual: the zero-initialised last layer made non-zero
        for p in f.parameters():
            p.add_(0.05 * torch.randn(p.shape, generator=gen))
    return f


def _points(ctx, n=300, seed=0):
    rng = np.random.default_rng(seed)
    v = ctx.vertices.detach()[rng.integers(0, len(ctx.vertices), n)]
    pts = v + torch.as_tensor(rng.normal(0, 0.015, v.shape), dtype=v.dtype)
    dirs = torch.as_tensor(rng.normal(size=v.shape), dtype=v.dtype)
    return pts, torch.nn.functional.normalize(dirs, dim=1)


def test_folded_pose_layer_matches_concatenation_values_and_gradients(field, monkeypatch):
    ctx = field.pose_feature.context(*preset("walk"))
    pts, dirs = _points(ctx)
    field.zero_grad()  # (a context per pass: the trainable encoder's maps are in the graph)
    sdf, rgb, valid = field.sdf_and_color(ctx, pts, dirs)
    (sdf.sum() + rgb.sum()).backward()
    fast = {n: p.grad.clone() for n, p in field.named_parameters() if p.grad is not None}
    monkeypatch.setattr(AvatarField, "_sdf_hidden", _concat_hidden)
    field.zero_grad()
    ctx = field.pose_feature.context(*preset("walk"))
    sdf0, rgb0, valid0 = field.sdf_and_color(ctx, pts, dirs)
    (sdf0.sum() + rgb0.sum()).backward()
    assert valid.any() and torch.equal(valid, valid0)
    assert (sdf - sdf0).abs().max() < 1e-5 and (rgb - rgb0).abs().max() < 1e-5
    assert sdf0.abs().max() > 0 and (sdf0 - sdf0.mean()).abs().max() > 1e-3  # not trivial
    for name, p in field.named_parameters():
        if p.grad is not None:
            assert torch.allclose(fast[name], p.grad, rtol=1e-4, atol=1e-6), name


def test_folded_pose_layer_renders_the_same_image(field, monkeypatch):
    pose, trans = preset("squat")
    cam = default_cameras(SynthSettings(size=256))[1].scaled(1 / 8)
    # no thresholds (scouting, early stop, empty rays): a float-rounding difference in
    # the field cannot flip a marching decision, so the images must agree to rounding
    settings = MarchSettings.from_flat(scout_threshold=None, early_stop_eps=0.0, empty_opacity=0.0)
    with torch.no_grad():
        ctx = field.pose_feature.context(pose, trans)
        shell = ShellGeometry.build(ctx.vertices, field.body.faces, settings.shell_width, index=ctx.index)
        fast = render_image(field.for_pose(ctx), cam, ctx.vertices, field.body.faces, settings, shell=shell)
        monkeypatch.setattr(AvatarField, "_sdf_hidden", _concat_hidden)
        slow = render_image(field.for_pose(ctx), cam, ctx.vertices, field.body.faces, settings, shell=shell)
    assert fast.alpha.max() > 0.5  # the body is in the picture
    assert (fast.rgb - slow.rgb).abs().max() < 1e-4
    assert (fast.alpha - slow.alpha).abs().max() < 1e-4


def test_normal_softplus_is_torch_softplus_to_float32_rounding_values_and_gradients():
    """The field's activation floors βx at -25 so no subnormal float appears: across the
    range a trained field's pre-activations cover (βx from -300 to 300) its values and
    gradients equal nn.Softplus(β=100)'s to 1e-12 absolute and float32 rounding relative."""
    x = torch.linspace(-3.0, 3.0, 200_001, dtype=torch.float32)
    a, b = x.clone().requires_grad_(), x.clone().requires_grad_()
    ya, yb = NormalSoftplus(beta=100)(a), torch.nn.Softplus(beta=100)(b)
    (ya.sum()).backward()
    (yb.sum()).backward()
    err = (ya - yb).abs()
    assert err.max() < 1e-12 and (err / yb.abs().clamp(min=1e-6)).max() < 1e-6
    assert (a.grad - b.grad).abs().max() < 1e-10
    assert torch.equal(ya[x > -0.2], yb[x > -0.2])  # above the floor: the same numbers
    assert not (ya != 0).logical_and(ya.abs() < torch.finfo(torch.float32).tiny).any()  # no subnormals
    assert (yb.abs() < torch.finfo(torch.float32).tiny).logical_and(yb != 0).any()  # torch's has them


def test_bfloat16_field_is_near_float32_and_keeps_its_outputs_float32(field):
    """render.precision=bfloat16: the MLPs' products in bf16, the body distance and the
    outputs float32; SDF and colour within bf16's rounding of the float32 ones."""
    ctx = field.pose_feature.context(*preset("walk"))
    pts, dirs = _points(ctx)
    with torch.no_grad():
        sdf, rgb = field.for_pose(ctx).sdf_rgb(pts, dirs)
        sdf16, rgb16 = field.for_pose(ctx, "bfloat16").sdf_rgb(pts, dirs)
        proj = field.pose_feature(ctx, pts, field.settings.shell_width)
    assert sdf16.dtype == rgb16.dtype == torch.float32
    inside = proj.valid
    residual = (sdf - proj.distance)[inside]
    assert inside.sum() > 100 and residual.abs().max() > 1e-3  # the residual is not trivial
    assert torch.equal(sdf16[~inside], sdf[~inside])  # no MLP beyond the shell
    assert 0 < (sdf16 - sdf)[inside].abs().max() < 0.02 * residual.abs().max()
    assert 0 < (rgb16 - rgb).abs().max() < 0.01
    with pytest.raises(ValueError, match="precision 'float16': expected one of float32, bfloat16, auto"):
        field.for_pose(ctx, "float16")


def test_bfloat16_render_is_near_the_float32_image(field):
    pose, trans = preset("squat")
    cam = default_cameras(SynthSettings(size=256))[1].scaled(1 / 4)
    settings = MarchSettings.from_flat(guide="raster")
    with torch.no_grad():
        ctx = field.pose_feature.context(pose, trans)
        images = [
            render_image(
                field.for_pose(ctx, p), cam, ctx.vertices, field.body.faces, settings, index=ctx.index
            )
            for p in ("float32", "bfloat16")
        ]
    a, b = images
    assert a.alpha.max() > 0.5 and b.rgb.dtype == torch.float32
    err = (a.rgb - b.rgb).abs()
    assert err.max() > 0  # bf16 changed something: the path was taken
    assert err.mean() < 2e-3 and (a.alpha - b.alpha).abs().mean() < 2e-3


@pytest.mark.parametrize("n", [1, 2])
def test_field_call_with_one_or_two_points_matches_the_batch(field, n):
    """A marcher chunk may hold a single point (the last sample of one ray)."""
    ctx = field.pose_feature.context(*preset("a_pose"))
    pts, dirs = _points(ctx, n=6, seed=3)
    with torch.no_grad():
        sigma, rgb = field(ctx, pts, dirs)
        small = field(ctx, pts[:n], dirs[:n])
    assert sigma.shape == (6,) and small[0].shape == (n,)
    assert torch.allclose(small[0], sigma[:n], rtol=1e-5, atol=1e-6)
    assert torch.allclose(small[1], rgb[:n], atol=1e-6)


def test_sample_pdf_on_a_zero_length_ray_is_finite():
    """A ray clipped to a zero-length interval (near == far after rounding) with zero
    weights: its importance samples sit at that point instead of NaN."""
    from texvocab.render import sample_pdf

    edges = torch.tensor([[0.0, 0.5, 1.0], [2.0, 2.0, 2.0]])
    weights = torch.tensor([[1.0, 3.0], [0.0, 0.0]])
    for gen in (None, torch.Generator().manual_seed(0)):
        u = sample_pdf(edges, weights, 8, gen)
        assert torch.isfinite(u).all()
        assert torch.equal(u[1], torch.full((8,), 2.0))
        assert (u[0] >= 0).all() and (u[0] <= 1).all() and (u[0] > 0.5).sum() >= 5


def _guided_frame(field, monkeypatch, **knobs):
    """A 64² guided render of the squat with ``knobs``; the image and how many points
    the mesh queries searched and took as known (every SurfaceIndex.project call)."""
    from texvocab.geometry.surface import SurfaceIndex

    counts = {"searched": 0, "known": 0}
    project = SurfaceIndex.project

    def counted(self, points, *args, known=None, **kw):
        k = 0 if known is None else int((np.asarray(known) >= 0).sum())
        counts["known"] += k
        counts["searched"] += len(points) - k
        return project(self, points, *args, known=known, **kw)

    pose, trans = preset("squat")
    cam = default_cameras(SynthSettings(size=256))[1].scaled(1 / 4)
    settings = MarchSettings.from_flat(guide="raster", **knobs)
    with torch.no_grad():
        ctx = field.pose_feature.context(pose, trans)
        monkeypatch.setattr(SurfaceIndex, "project", counted)
        image = render_image(
            field.for_pose(ctx), cam, ctx.vertices, field.body.faces, settings, index=ctx.index
        )
        monkeypatch.setattr(SurfaceIndex, "project", project)
    return image, counts


def test_surface_reuse_renders_the_searched_image_with_fewer_searches(field, monkeypatch):
    """The guided marcher hands the field the closest faces it knows (a hit probe's raster
    face, a residual ray's evaluations on its mesh samples): the same image as searching
    every point, with three points per residual ray and the hit probes fewer searches."""
    new, reuse = _guided_frame(field, monkeypatch)
    old, search = _guided_frame(field, monkeypatch, surface_reuse=False)
    paths = new.stats.paths
    assert paths["residual"] > 100 and paths["fallback"] > 10  # the tiny field's rough residual
    _same_image(new, old)
    assert search["known"] == 0 and reuse["known"] > 3 * paths["residual"]
    assert reuse["searched"] <= search["searched"] - reuse["known"]


def test_grouped_residual_quadrature_renders_the_padded_image(field, monkeypatch):
    """The residual rays' quadrature in groups of similar sample counts gives the image
    of one array padded to the longest ray (torch's quadrature, as training runs it; a
    render takes the compiled one, which has no groups)."""
    import texvocab.render.guided.residual as residual

    monkeypatch.setattr(residual, "quadrature_compiled", False)
    grouped, _ = _guided_frame(field, monkeypatch, residual_groups=4)
    padded, _ = _guided_frame(field, monkeypatch, residual_groups=1)
    assert grouped.stats.paths["residual"] > 100
    _same_image(grouped, padded)


def _same_image(a, b) -> None:
    """Two renders of one frame by equivalent computations: float rounding may move a
    residual ray's quantile by one mesh sample (a colour change of ~1e-4 at a pixel), so
    the images agree to 1e-3 at any pixel and 1e-6 on average, the kinds at 99.5 %."""
    assert (a.stats.kind != b.stats.kind).float().mean() <= 0.005
    for x, y in ((a.rgb, b.rgb), (a.alpha, b.alpha)):
        err = (x - y).abs()
        assert err.max() < 1e-3 and err.mean() < 1e-6
