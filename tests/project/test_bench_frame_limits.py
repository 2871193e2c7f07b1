"""bench/frame_limits.py: each stage of a frame and of a training step against the matrix
products' rate measured in the same run; the stages add up to the whole, and the field's
FLOP count is its MLPs' multiply-adds."""

import sys
from pathlib import Path

import pytest
import torch
from tiny_runs import smallest_run

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))

import frame_limits  # noqa: E402

from texvocab.pipeline.avatar import load_avatar  # noqa: E402


@pytest.fixture(scope="module")
def ckpt(tmp_path_factory):
    return smallest_run(tmp_path_factory.mktemp("run"))


def test_field_flops_count_the_mlps_multiply_adds_without_the_folded_pose(ckpt):
    model = load_avatar(ckpt, progress=False).model
    macs = sum(
        m.in_features * m.out_features
        for net in (model.feature_proj, model.sdf_net, model.color_net)
        for m in net.modules()
        if isinstance(m, torch.nn.Linear)
    )
    folded = 4 * model.body.num_joints * model.settings.hidden  # the pose's first-layer columns
    assert frame_limits.field_flops(model) == pytest.approx(2 * (macs - folded))
    assert 0 < frame_limits.field_flops(model) < 2 * macs


def test_the_bench_prints_the_limits_the_stages_and_a_summary(ckpt, capsys):
    argv = [
        str(ckpt),
        "--frames",
        "1",
        "--repeats",
        "1",
        "--steps",
        "2",
        "--warmup",
        "1",
        "--gemm-seconds",
        "0.05",
    ]
    assert frame_limits.main(argv) == 0
    out = capsys.readouterr().out
    lines = out.strip().splitlines()
    summary = dict(kv.split("=") for kv in lines[-1].removeprefix("summary: ").split())
    assert set(summary) == {"frame_s", "step_s", "sgemm_gflops", "bf16_gflops"}
    assert float(summary["frame_s"]) > 0 and float(summary["sgemm_gflops"]) > 1
    frame = out.split("## a frame")[1].split("## a training step")[0]
    rows = {r.split("|")[1].strip(): r.split("|")[2:-1] for r in frame.splitlines() if r.startswith("| ")}
    for stage in ("pose context", "plan (raster)", "probe", "**total**"):
        assert stage in rows, stage
    parts = sum(float(v[0]) for k, v in rows.items() if k not in ("stage", "---", "**total**"))
    total = float(rows["**total**"][0].strip(" *"))
    assert parts == pytest.approx(total, rel=0.1)  # nested stages are not counted twice
    assert int(rows["probe"][2].replace(",", "")) > 0  # the probe evaluated the field
    assert "| backward |" in out.split("## a training step")[1]


def test_bf16_rates_are_not_measured_where_the_cpu_emulates_bf16(monkeypatch):
    """Without bf16 units torch emulates bf16 products at a few GFLOP/s (a 2048³ product
    then takes minutes): the limits leave them out (nan) and measure float32."""
    import math

    from texvocab.method import field_precision as field

    monkeypatch.setattr(field, "native_bfloat16", lambda: False)
    limits = frame_limits.machine_limits(0.01)
    assert math.isnan(limits["bf16"]) and math.isnan(limits["bf16_mlp"])
    assert limits["sgemm"] > 1 and limits["sgemm_mlp"] > 1
