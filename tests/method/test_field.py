"""Avatar field: geometric initialisation, inverse LBS, VolSDF density at the extremes."""

import numpy as np
import pytest
import torch

from texvocab.body import default_body
from texvocab.body.poses import preset
from texvocab.method.encoder import build_encoder
from texvocab.method.feature import PoseFeature
from texvocab.method.field import AvatarField, FieldSettings, laplace_density, positional_encoding
from texvocab.method.vocab import Vocabulary


@pytest.fixture(scope="module")
def field():
    body = default_body()
    vocab = Vocabulary.build(np.random.default_rng(0).normal(0, 0.2, (4, 24, 3)), num_keys=4, k=2)
    pf = PoseFeature(body, vocab, torch.rand(4, 3, 32, 32), build_encoder("small"))
    torch.manual_seed(0)
    return AvatarField(pf, FieldSettings(hidden=32))


def test_initial_sdf_is_the_posed_body(field):
    body = field.body
    pose, trans = preset("walk")
    ctx = field.pose_feature.context(pose, trans)
    v = ctx.vertices[::50].detach()
    normals = torch.nn.functional.normalize(v - v.mean(0), dim=-1)  # rough outward
    pts = torch.cat([v, v + 0.01 * normals])
    sdf, rgb, valid = field.sdf_and_color(ctx, pts, torch.nn.functional.normalize(pts, dim=-1))
    assert valid.all()
    assert sdf[: len(v)].abs().max() < 1e-5  # on the surface
    assert rgb.min() >= 0 and rgb.max() <= 1
    del body


def test_canonicalize_inverts_lbs(field):
    body = field.body
    pose, trans = preset("squat")
    ctx = field.pose_feature.context(pose, trans)
    x_c = field.canonicalize(ctx, ctx.vertices.detach(), body.weights)
    assert torch.allclose(x_c, body.v_template, atol=1e-4)


def test_eikonal_gradient_of_the_initial_sdf_is_unit(field):
    ctx = field.pose_feature.context(np.zeros((24, 3)))
    rng = np.random.default_rng(1)
    v = ctx.vertices.detach()[rng.integers(0, len(ctx.vertices), 200)]
    pts = (v + torch.as_tensor(rng.normal(0, 0.01, v.shape), dtype=v.dtype)).requires_grad_()
    sdf, _, valid = field.sdf_and_color(ctx, pts, torch.zeros_like(pts) + torch.tensor([0, 0, 1.0]))
    (grad,) = torch.autograd.grad(sdf.sum(), pts)
    norms = grad[valid].norm(dim=-1)
    assert torch.isfinite(grad).all() and (norms - 1).abs().max() < 1e-4


@pytest.mark.parametrize("beta", [1e-8, 1e-4, 1e-2, 1.0, 1e3])
def test_laplace_density_is_finite_at_extreme_beta(beta):
    sdf = torch.tensor([-1e3, -1.0, -1e-6, 0.0, 1e-6, 1.0, 1e3], requires_grad=True)
    b = torch.tensor(beta, requires_grad=True)
    sigma = laplace_density(sdf, b)
    sigma.sum().backward()
    assert torch.isfinite(sigma).all() and torch.isfinite(sdf.grad).all()
    assert torch.isfinite(b.grad)
    assert sigma[0] >= sigma[3] >= sigma[-1]  # denser inside
    assert float(sigma[3].detach()) == pytest.approx(0.5 / beta, rel=1e-6)


def test_positional_encoding_shape():
    x = torch.rand(5, 3)
    assert positional_encoding(x, 4).shape == (5, 27)


def test_pose_field_serves_both_marchers_down_to_one_point(field):
    """PoseField: density for the shell marcher, SDF for the guided one (the same
    VolSDF pair), beta as a float; a single point works (the viewer once padded those)."""
    from texvocab.method.field import laplace_density

    ctx = field.pose_feature.context(*preset("walk"))
    pf = field.for_pose(ctx)
    with torch.no_grad():
        for n in (1, 7):
            pts = ctx.vertices[:n].detach() + 0.003
            dirs = torch.nn.functional.normalize(pts, dim=-1)
            sigma, rgb = pf(pts, dirs)
            sdf, rgb2 = pf.sdf_rgb(pts, dirs)
            assert sigma.shape == (n,) and sdf.shape == (n,) and torch.equal(rgb, rgb2)
            assert torch.allclose(sigma, laplace_density(sdf, field.beta), rtol=1e-5)
    assert isinstance(pf.beta, float) and pf.beta == pytest.approx(float(field.beta))
