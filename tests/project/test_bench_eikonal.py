"""bench/eikonal_gradient.py: the eikonal term's autograd gradient against finite
differences of the whole SDF. On a field whose residual ignores the texture feature and
the skinning weights (zero SDF network output), the two must agree (what autograd leaves
out is then zero); on a trained one the table and the summary line are printed."""

import sys
from pathlib import Path

import torch
from tiny_runs import smallest_run

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))

import eikonal_gradient  # noqa: E402

from texvocab.pipeline.avatar import load_avatar  # noqa: E402


def test_gradients_agree_where_the_sdf_is_the_body_distance(tmp_path):
    ckpt = smallest_run(tmp_path)
    avatar = load_avatar(ckpt, progress=False)
    model, cap = avatar.model, avatar.capture
    with torch.no_grad():  # the SDF network's residual: zero everywhere
        model.sdf_net[-1].weight.zero_()
        model.sdf_net[-1].bias.zero_()
    ctx = model.pose_feature.context(cap.poses[0], cap.trans[0])
    verts = ctx.vertices.detach()
    pts = verts[:200] + 0.004 * torch.randn(200, 3, generator=torch.Generator().manual_seed(0))
    g_auto, g_fd, ok = eikonal_gradient.gradients(model, ctx, pts, 1e-4)
    assert ok.sum() > 100
    # the body distance alone: both gradients are its unit gradient (jumps aside)
    rel = ((g_auto - g_fd) ** 2).sum(1) ** 0.5
    assert (rel[ok] < 0.05).mean() > 0.95


def test_the_bench_prints_its_table_and_summary(tmp_path, capsys):
    ckpt = smallest_run(tmp_path)
    assert eikonal_gradient.main([str(ckpt), "--frames", "1", "--points", "64", "--eps", "1e-3"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].startswith("| checkpoint |") and len(lines) == 4
    assert lines[-1].startswith("summary: rel_median=") and "nan" not in lines[-1]
