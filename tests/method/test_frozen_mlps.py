"""The field's MLPs frozen at one pose for rendering (texvocab.method.frozen_mlps) and the
bfloat16 activation table (texvocab.method.activation_table): the same numbers as the
autocast path, to the bit, rebuilt when the weights change, and never used with autograd."""

import numpy as np
import pytest
import torch

from texvocab.body import default_body
from texvocab.body.poses import preset
from texvocab.method.activation_table import ActivationTable
from texvocab.method.encoder import build_encoder
from texvocab.method.feature import PoseFeature
from texvocab.method.field import AvatarField, FieldSettings, NormalSoftplus
from texvocab.method.vocab import Vocabulary


@pytest.fixture(scope="module", params=["frequencies", "triplane"])
def field(request):
    body = default_body()
    vocab = Vocabulary.build(np.random.default_rng(0).normal(0, 0.2, (4, 24, 3)), num_keys=4, k=2)
    pf = PoseFeature(body, vocab, torch.rand(4, 3, 32, 32), build_encoder("small"))
    torch.manual_seed(0)
    # both position encodings: γ(x_c) alone, and with tri-plane features (texvocab.method.triplane)
    f = AvatarField(pf, FieldSettings(hidden=32, position_encoding=request.param, triplane_resolution=16))
    with torch.no_grad():  # a trained-looking field: the residual's last layer away from zero
        for p in f.parameters():
            p.add_(0.3 * torch.randn_like(p))
    return f.eval()


def _points(ctx, n=600, seed=0):
    g = torch.Generator().manual_seed(seed)
    v = ctx.vertices.detach()
    pts = v[torch.randint(0, len(v), (n,), generator=g)] + 0.02 * torch.randn(n, 3, generator=g)
    dirs = torch.nn.functional.normalize(torch.randn(n, 3, generator=g), dim=-1)
    return pts, dirs


def test_activation_table_is_the_function_to_the_bit():
    act = NormalSoftplus(beta=100)
    table = ActivationTable(act)
    bits = torch.arange(-32768, 32768, dtype=torch.int32).to(torch.int16).view(torch.bfloat16)
    x = torch.cat([bits, torch.randn(3000).bfloat16() * 0.1]).reshape(-1, 8)
    got, want = table(x), act(x)
    same = (got.view(torch.int16) == want.view(torch.int16)) | (got.isnan() & want.isnan())
    assert got.dtype == torch.bfloat16 and got.shape == x.shape and bool(same.all())
    assert table(x[:, ::2]).shape == (x.shape[0], 4)  # a strided view
    with pytest.raises(ValueError, match="bfloat16"):
        table(torch.zeros(3))


@pytest.mark.parametrize("precision", ["bfloat16", "float32"])
def test_frozen_mlps_give_the_autocast_numbers(field, precision):
    ctx = field.pose_feature.context(*preset("walk"))
    pts, dirs = _points(ctx)
    pose_field = field.for_pose(ctx, precision)
    with torch.no_grad():
        assert pose_field.frozen() is not None
        sdf, rgb = pose_field.sdf_rgb(pts, dirs)
        ref_sdf, ref_rgb, valid = field.sdf_and_color(ctx, pts, dirs, precision)
        density, rgb2 = pose_field(pts, dirs)
        ref_density, _ = field(ctx, pts, dirs, precision)
    assert valid.sum() > 100 and (~valid).sum() > 0
    assert torch.equal(sdf[valid], ref_sdf[valid]) and torch.equal(rgb, ref_rgb)
    assert torch.equal(density, ref_density) and torch.equal(rgb2, rgb)


def test_frozen_mlps_follow_the_weights_and_stay_out_of_autograd(field):
    ctx = field.pose_feature.context(*preset("squat"))
    pts, dirs = _points(ctx, 300, seed=1)
    pose_field = field.for_pose(ctx, "bfloat16")
    with torch.no_grad():
        first = pose_field.frozen()
        before, _ = pose_field.sdf_rgb(pts, dirs)
        assert pose_field.frozen() is first  # made once per pose
        layer = field.sdf_net[-1]
        saved = layer.bias.clone()
        layer.bias.add_(0.05)  # an optimiser step changes the weights in place
        try:
            after, _ = pose_field.sdf_rgb(pts, dirs)
            assert pose_field.frozen() is not first  # rebuilt
            ref, _, valid = field.sdf_and_color(ctx, pts, dirs, "bfloat16")
            assert torch.equal(after[valid], ref[valid]) and not torch.equal(after, before)
        finally:
            layer.bias.copy_(saved)
    assert pose_field.frozen() is None  # autograd on: the autocast path, with gradients
    sdf, _ = pose_field.sdf_rgb(pts, dirs)
    sdf.sum().backward()
    assert field.sdf_net[0].weight.grad is not None and field.sdf_net[0].weight.grad.abs().sum() > 0
    field.zero_grad(set_to_none=True)
