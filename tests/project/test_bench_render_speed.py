"""bench/render_speed.py --compare: five paths in one run, the default path as it was
(float32, torch's softplus) beside it, and a last line that ends with the PSNR delta."""

import sys
from pathlib import Path

import torch
from tiny_runs import smallest_run

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))

import render_speed  # noqa: E402
import render_timing  # noqa: E402

from texvocab.method.field import NormalSoftplus  # noqa: E402
from texvocab.pipeline.avatar import load_avatar  # noqa: E402


def test_compare_ends_with_speedup_and_psnr_delta(tmp_path, capsys):
    ckpt = smallest_run(tmp_path)
    args = [str(ckpt), "--compare", "--frames", "1", "--variant", "step3:residual_step=3"]
    assert render_speed.main(args) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[-1].startswith("summary: new_s=")
    summary = dict(kv.split("=") for kv in lines[-1].removeprefix("summary: ").split())
    assert list(summary)[-1] == "psnr_delta_db"
    assert {"previous_s", "new_evals", "previous_evals", "speedup"} <= set(summary)
    assert float(summary["speedup"]) > 0 and abs(float(summary["psnr_delta_db"])) < 0.1
    rows = [r.split("|")[1].strip() for r in lines if r.startswith("| ") and "frame" in r]
    assert {"new", "previous", "shell", "quality", "reference", "step3"} <= set(rows)


def test_the_previous_path_swaps_torchs_softplus_in_for_the_run_only(tmp_path):
    model = load_avatar(smallest_run(tmp_path), progress=False).model

    def acts():
        nets = (model.sdf_net, model.color_net)
        return [type(m) for net in nets for m in net if not isinstance(m, torch.nn.Linear)]

    before = acts()
    assert before and all(t is NormalSoftplus for t in before)
    with render_timing.plain_softplus(model, True):
        assert all(t is torch.nn.Softplus for t in acts())
    assert acts() == before


def test_the_previous_path_searches_with_the_plain_kernel_for_the_run_only():
    from texvocab.geometry import _nearest_jit, surface
    from texvocab.render.guided import residual

    assert surface.nearest_faces is _nearest_jit.nearest_faces
    assert residual.mesh_samples is residual.compiled_mesh_samples
    with render_timing.plain_search(True):
        assert surface.nearest_faces is _nearest_jit.nearest_faces_plain
        assert residual.mesh_samples is residual.padded_mesh_samples
    assert surface.nearest_faces is _nearest_jit.nearest_faces
    assert residual.mesh_samples is residual.compiled_mesh_samples
    assert render_timing.BEFORE == {
        "surface_reuse": False,
        "residual_groups": 1,
        "residual_levels": 0,
        "fallback_segment": 8,
        "fallback_grid_rays": 0,
        "miss_reach": "margin",
        "band_retries": 0,
    }
