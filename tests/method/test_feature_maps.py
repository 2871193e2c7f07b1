"""FeatureMaps: all of a pose's key maps sampled in one call equal the per-map sum of
bilinear samples, values and gradients, and a frozen encoder's maps are shared."""

import torch

from texvocab.method.feature_maps import FeatureMaps, sample_maps


def test_one_call_equals_the_per_map_sum_with_gradients():
    g = torch.Generator().manual_seed(0)
    maps = torch.randn(4, 5, 7, 9, generator=g, dtype=torch.float64, requires_grad=True)
    uv = torch.rand(200, 2, generator=g, dtype=torch.float64) * 1.2 - 0.1
    coef = torch.rand(200, 4, generator=g, dtype=torch.float64)
    coef[coef < 0.5] = 0  # sparse: about half the (point, map) pairs are skipped
    coef[:10] = 0  # points attending to nothing
    fm = FeatureMaps.from_stack(maps)
    got = fm.sample(uv, coef)
    ref = sum(coef[:, u : u + 1] * sample_maps(maps[u], uv) for u in range(4))
    assert torch.allclose(got, ref, atol=1e-12)
    assert torch.equal(got[:10], torch.zeros_like(got[:10]))
    (ga,) = torch.autograd.grad((got * ref.detach()).sum(), maps)
    (gb,) = torch.autograd.grad((ref * ref.detach()).sum(), maps)
    assert torch.allclose(ga, gb, atol=1e-10)
    assert torch.equal(fm.stack(), maps.detach())


def test_rows_pick_maps_out_of_a_shared_table():
    g = torch.Generator().manual_seed(1)
    all_maps = FeatureMaps.from_stack(torch.randn(6, 3, 4, 5, generator=g))
    picked = FeatureMaps(all_maps.table, torch.tensor([4, 1]) * 20, 4, 5)
    assert picked.table.data_ptr() == all_maps.table.data_ptr()  # no copy per pose
    assert torch.equal(picked.map(0), all_maps.map(4)) and torch.equal(picked.map(1), all_maps.map(1))
    uv = torch.rand(50, 2, generator=g)
    coef = torch.rand(50, 2, generator=g)
    ref = coef[:, :1] * sample_maps(all_maps.map(4), uv) + coef[:, 1:] * sample_maps(all_maps.map(1), uv)
    assert torch.allclose(picked.sample(uv, coef), ref, atol=1e-6)
