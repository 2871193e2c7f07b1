"""Tri-plane position features (texvocab.method.triplane, field.position_encoding=triplane):
bilinear in each plane, exact first and second derivatives in x_c, a new field that starts
as the plain one, and the planes' own learning rate (the render path's numbers:
test_frozen_mlps.py)."""

from types import SimpleNamespace

import numpy as np
import pytest
import torch

from texvocab.body import default_body
from texvocab.body.poses import preset
from texvocab.method.encoder import build_encoder
from texvocab.method.feature import PoseFeature
from texvocab.method.field import AvatarField, FieldSettings
from texvocab.method.triplane import CanonicalTriplane, canonical_box
from texvocab.method.vocab import Vocabulary
from texvocab.pipeline.param_groups import optimizer_groups


def _planes(res=5, ch=2, seed=0):
    tri = CanonicalTriplane(torch.zeros(3), torch.tensor([1.0, 2.0, 4.0]), res, ch).double()
    with torch.no_grad():
        tri.planes.copy_(torch.randn(tri.planes.shape, generator=torch.Generator().manual_seed(seed)))
    return tri


def test_triplane_reads_texels_at_their_centres_and_interpolates_bilinearly_between():
    tri = _planes()
    r = tri.resolution
    planes = tri.planes.detach().reshape(3, r, r, tri.channels)
    i, j, k = 1, 3, 2  # a grid node: x = i / (r-1) of each axis' extent
    x = torch.tensor([[i / (r - 1) * 1.0, j / (r - 1) * 2.0, k / (r - 1) * 4.0]], dtype=torch.float64)
    got = tri(x)[0].reshape(3, tri.channels)
    assert torch.allclose(got[0], planes[0, i, j]) and torch.allclose(got[1], planes[1, i, k])
    assert torch.allclose(got[2], planes[2, j, k])
    # halfway along x between two nodes: the mean of their texels on the planes that see x
    half = x + torch.tensor([[0.5 / (r - 1), 0, 0]], dtype=torch.float64)
    mid = tri(half)[0].reshape(3, tri.channels)
    assert torch.allclose(mid[0], (planes[0, i, j] + planes[0, i + 1, j]) / 2)
    assert torch.allclose(mid[2], planes[2, j, k])  # the yz plane does not see x
    # outside the box a point reads the box's edge
    far = tri(torch.tensor([[-3.0, 9.0, 0.0]], dtype=torch.float64))[0].reshape(3, tri.channels)
    assert torch.allclose(far[0], planes[0, 0, r - 1])


def test_triplane_gradients_in_x_are_exact_to_second_order():
    tri = _planes()
    x = (
        torch.rand(20, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
        * torch.tensor([1.0, 2.0, 4.0], dtype=torch.float64)
    ).requires_grad_()
    w = torch.randn(tri.out_dim, dtype=torch.float64)

    def f(p):
        return (tri(p) @ w).sum()

    assert torch.autograd.gradcheck(f, (x,))
    # the eikonal term differentiates the gradient again, with respect to the planes
    (g,) = torch.autograd.grad(f(x), x, create_graph=True)
    (g.norm(dim=-1) - 1).square().sum().backward()
    assert tri.planes.grad is not None and tri.planes.grad.abs().sum() > 0


def _field(settings):
    body = default_body()
    vocab = Vocabulary.build(np.random.default_rng(0).normal(0, 0.2, (4, 24, 3)), num_keys=4, k=2)
    pf = PoseFeature(body, vocab, torch.rand(4, 3, 32, 32), build_encoder("small"))
    torch.manual_seed(0)
    return AvatarField(pf, settings)


def _points(ctx, n=500):
    g = torch.Generator().manual_seed(2)
    v = ctx.vertices.detach()
    pts = v[torch.randint(0, len(v), (n,), generator=g)] + 0.02 * torch.randn(n, 3, generator=g)
    return pts, torch.nn.functional.normalize(torch.randn(n, 3, generator=g), dim=-1)


def test_a_new_triplane_field_starts_as_the_plain_one():
    plain = _field(FieldSettings(hidden=32, position_encoding="frequencies"))
    tri = _field(FieldSettings(hidden=32, position_encoding="triplane", triplane_resolution=16))
    lo, hi = canonical_box(plain.body.v_template, 0.15)
    assert torch.equal(tri.triplane.lo, lo) and torch.equal(tri.triplane.hi, hi)
    assert tri.position_dim == plain.position_dim + 3 * 8
    with torch.no_grad():  # the plain field's weights; the planes' input columns as initialised
        plain_params = dict(plain.named_parameters())
        for name, p in tri.named_parameters():
            if name.startswith("triplane"):
                continue
            src = plain_params[name]
            if name == "sdf_net.0.weight":
                d = plain.position_dim
                p[:, :d] = src[:, :d]
                p[:, d + 24 :] = src[:, d:]
            else:
                p.copy_(src)
        for p in (plain.sdf_net[-1].weight, tri.sdf_net[-1].weight):  # a residual away from zero
            p.copy_(torch.linspace(-0.3, 0.3, p.numel()).reshape(p.shape))
    ctx = plain.pose_feature.context(*preset("walk"))
    pts, dirs = _points(ctx)
    a = plain.sdf_and_color(ctx, pts, dirs)
    b = tri.sdf_and_color(ctx, pts, dirs)
    assert torch.allclose(a[0], b[0], atol=1e-6) and torch.allclose(a[1], b[1], atol=1e-6)
    with torch.no_grad():
        tri.triplane.planes.normal_(0, 1)
    assert not torch.allclose(tri.sdf_and_color(ctx, pts, dirs)[0], a[0], atol=1e-3)  # the planes count


def test_planes_and_beta_learn_at_their_own_rates():
    field = _field(FieldSettings(hidden=16, position_encoding="triplane", triplane_resolution=8))
    train = SimpleNamespace(lr=1e-3, beta_lr_scale=10.0, triplane_lr_scale=20.0)
    groups = optimizer_groups(field, train)
    ids = [id(p) for g in groups for p in g["params"]]
    assert sorted(ids) == sorted(id(p) for p in field.parameters()) and len(set(ids)) == len(ids)
    assert [g.get("lr") for g in groups] == [None, pytest.approx(1e-2), pytest.approx(2e-2)]
    assert groups[2]["params"] == [field.triplane.planes] and groups[1]["params"] == [field.log_beta]
    plain = optimizer_groups(field, SimpleNamespace(lr=1e-3, beta_lr_scale=1.0, triplane_lr_scale=1.0))
    assert len(plain) == 1  # every part at the plain rate: one group, as before the planes


def test_the_settings_are_checked():
    from texvocab.errors import TexvocabError
    from texvocab.pipeline.settings import Settings

    s = Settings().with_overrides(["field.position_encoding=triplane", "train.triplane_lr_scale=5"])
    assert s.field.position_encoding == "triplane" and s.train.triplane_lr_scale == 5
    assert Settings().field.position_encoding == "triplane"
    with pytest.raises(TexvocabError, match="position_encoding"):
        Settings().with_overrides(["field.position_encoding=hashgrid"])
    with pytest.raises(TexvocabError, match="triplane_resolution"):
        Settings().with_overrides(["field.triplane_resolution=1"])


def test_a_checkpoint_from_before_the_planes_keeps_its_plain_field():
    from texvocab.pipeline.settings import Settings

    d = Settings().to_dict()
    del d["field"]["position_encoding"]
    assert Settings.from_dict(d).field.position_encoding == "frequencies"


def test_a_non_finite_point_reads_a_finite_feature_and_the_lookup_stays_in_the_table():
    tri = CanonicalTriplane(torch.zeros(3), torch.ones(3), 4, 2)
    with torch.no_grad():
        tri.planes.normal_()
    x = torch.tensor([[float("nan"), 0.5, 0.5], [float("inf"), -float("inf"), 0.5], [0.5, 0.5, 0.5]])
    out = tri(x)
    assert out.shape == (3, 6) and torch.isfinite(out).all()
    assert torch.equal(out[1], tri(torch.tensor([[1.0, 0.0, 0.5]]))[0])  # ±inf: the box's edge
