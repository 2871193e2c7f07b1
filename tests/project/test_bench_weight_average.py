"""bench/weight_average.py: one run with the weight average on, continued a few steps at
a time; at each stop its raw weights and their average scored on the same images and
paired; finished stops reused; bad input one error line."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from train_cases import SMALLEST_SET

from texvocab.io.checkpoint import load_checkpoint
from texvocab.pipeline.weight_average import TRAINED_KEY

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "bench" / "weight_average.py"


@pytest.mark.slow  # a short training run, resumed once, and four evaluations in subprocesses
def test_raw_and_averaged_weights_scored_at_each_stop(capture, tmp_path):
    out = tmp_path / "avg"
    cmd = [sys.executable, str(SCRIPT), str(capture), "--out", str(out), "--steps", "3", "--every", "2"]
    cmd += ["--stops", "2", "--decay", "0.5", "--per-set", "2", "--preset", "fast"]
    cmd += [a for s in SMALLEST_SET for a in ("--set", s)]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    last = run.stdout.strip().splitlines()[-1]
    fields = dict(kv.split("=") for kv in last.removeprefix("summary: ").split())
    assert fields["stops"] == "2" and fields["first_step"] == "3" and fields["last_step"] == "5"
    blob = json.loads((out / "weight_average.json").read_text())
    for stop in blob["stops"]:
        raw = load_checkpoint(out / f"step{stop['step']}" / "raw.pt")
        averaged = load_checkpoint(out / f"step{stop['step']}" / "averaged.pt")
        assert raw["step"] == averaged["step"] == stop["step"]
        assert TRAINED_KEY not in raw and raw["settings"]["train"]["weight_average"] == 0.0
        trained = averaged[TRAINED_KEY]["parameters"]
        assert all(torch.equal(raw["model"][k], v) for k, v in trained.items())
        assert any(not torch.equal(averaged["model"][k], v) for k, v in trained.items())
        raw_psnr, avg_psnr = stop["raw"]["psnr_bbox"], stop["averaged"]["psnr_bbox"]
        assert np.mean(stop["paired"]) == pytest.approx(avg_psnr - raw_psnr, abs=2e-3)
    means = [s["raw"]["psnr_bbox"] for s in blob["stops"]]
    assert float(fields["raw_swing"]) == pytest.approx(max(means) - min(means), abs=2e-3)
    # a second call reuses every stop
    stamp = (out / "step5" / "averaged.pt").stat().st_mtime_ns
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr
    assert again.stdout.strip().splitlines()[-1] == last
    assert (out / "step5" / "averaged.pt").stat().st_mtime_ns == stamp


def test_bad_arguments_are_one_error_line_and_write_nothing(capture, tmp_path):
    out = tmp_path / "avg"
    for args, message in (
        ([str(tmp_path / "nope")], f"error: {tmp_path / 'nope'}: not a capture folder"),
        ([str(capture), "--decay", "1"], "error: --decay 1.0: expected 0 < decay < 1"),
    ):
        run = subprocess.run(
            [sys.executable, str(SCRIPT), *args, "--out", str(out)], capture_output=True, text=True
        )
        assert run.returncode != 0
        assert run.stderr.strip().splitlines() == [message]
        assert not out.exists()
