"""bench/real_capture.py end to end on a HumanNeRF-layout stand-in: the body against the
masks, prepare, a time-budgeted train, eval of the held-out frames, the report."""

import json
import subprocess
import sys
from pathlib import Path

import pytest
from humannerf_cases import make_truth, write_standin

from texvocab.body import default_body

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow  # the command line end to end in subprocesses
def test_real_capture_bench_reports_the_fit_and_the_held_out_frames(tmp_path):
    body = default_body()
    cap = write_standin(tmp_path / "subject", body, make_truth(body), pelvis_offset=(0, -0.02, 0))
    before = sorted(p.relative_to(cap) for p in cap.rglob("*"))
    out = tmp_path / "bench"
    run = subprocess.run(
        [
            sys.executable,
            str(ROOT / "bench" / "real_capture.py"),
            str(cap),
            "--out",
            str(out),
            "--minutes",
            "0.05",
            "--fit-every",
            "3",
            "--coverage-every",
            "5",
            "--set",
            "vocab.encoder=small",
            "--set",
            "field.hidden=32",
            "--set",
            "data.texture_size=64",
            "--set",
            "vocab.num_keys=4",
            "--set",
            "vocab.k=2",
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    last = run.stdout.strip().splitlines()[-1]
    assert last.startswith("summary: novel_psnr_bbox=") and "fit_iou_after=" in last
    r = json.loads((out / "real_capture.json").read_text())
    assert r["capture_info"]["views"] == 1 and r["capture_info"]["novel_frames"] == 2
    assert r["table"]["novel_poses"]["images"] == 2 and r["steps"] >= 1
    assert r["table"]["training_poses"]["views"] == "seen view"
    assert 0 <= r["table"]["novel_poses"]["iou"] <= 1
    b = r["body"]
    assert all(0 < b[n]["iou_mean"] <= 1 for n in ("default", "fitted"))
    cov = [b["coverage"][k] for k in ("0.02", "0.04", "0.06", "0.08", "0.1")]
    assert cov == sorted(cov)
    assert "| fitted |" in (out / "real_capture.md").read_text()
    after = sorted(p.relative_to(cap) for p in cap.rglob("*") if "texvocab_cache" not in p.parts)
    assert after == [p for p in before]  # only texvocab's cache was added
