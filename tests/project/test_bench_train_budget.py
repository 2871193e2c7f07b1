"""bench/train_budget.py: a reference run and a shorter one with settings of its own,
trained one after the other with time budgets, scored on the same novel images and paired;
finished runs reused; bad input one error line."""

import json
import subprocess
import sys
from pathlib import Path

import pytest
from train_cases import SMALLEST_SET

from texvocab.io.checkpoint import load_checkpoint

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "bench" / "train_budget.py"


def _sets(flag: str, items: list[str]) -> list[str]:
    return [a for s in items for a in (flag, s)]


@pytest.mark.slow  # two short training runs and their evaluations in subprocesses
def test_two_budgets_scored_on_the_same_images_and_paired(capture, tmp_path):
    out = tmp_path / "budget"
    cmd = [sys.executable, str(SCRIPT), str(capture), "--out", str(out), "--minutes", "0.02"]
    cmd += ["--reference-minutes", "0.04", "--per-set", "2", "--preset", "fast"]
    cmd += _sets("--set", [*SMALLEST_SET, "lr_decay=0.1"]) + _sets("--reference-set", SMALLEST_SET)
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    last = run.stdout.strip().splitlines()[-1]
    fields = dict(kv.split("=") for kv in last.removeprefix("summary: ").split())
    assert fields["short_minutes"] == "0.02" and fields["reference_minutes"] == "0.04"
    assert int(fields["images"]) == 2
    blob = json.loads((out / "train_budget.json").read_text())
    short, ref = (load_checkpoint(out / name / "checkpoint.pt") for name in ("short", "reference"))
    assert short["settings"]["train"]["lr_decay"] == 0.1 and ref["settings"]["train"]["lr_decay"] == 1.0
    assert short["settings"]["train"]["max_minutes"] == 0.02
    assert int(fields["short_steps"]) == short["step"] >= 1 and int(fields["reference_steps"]) == ref["step"]
    # the paired difference over the same images is the difference of the means
    means = blob["short"]["row"]["psnr_bbox"] - blob["reference"]["row"]["psnr_bbox"]
    assert float(fields["delta_db"]) == pytest.approx(means, abs=2e-3)
    # a second call reuses both runs and their reports
    stamp = (out / "short" / "checkpoint.pt").stat().st_mtime_ns
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr
    assert again.stdout.strip().splitlines()[-1] == last
    assert (out / "short" / "checkpoint.pt").stat().st_mtime_ns == stamp
    # a run stopped before its budget was spent is refused, not taken as finished
    (out / "short" / "budget_spent").unlink()
    stopped = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert stopped.returncode != 0
    assert stopped.stderr.strip().splitlines()[-1].startswith(f"error: {out / 'short'}: a run that did not")


def test_a_missing_capture_is_one_error_line_and_writes_nothing(tmp_path):
    out = tmp_path / "budget"
    run = subprocess.run(
        [sys.executable, str(SCRIPT), str(tmp_path / "nope"), "--out", str(out)],
        capture_output=True,
        text=True,
    )
    assert run.returncode != 0
    assert run.stderr.strip().splitlines() == [f"error: {tmp_path / 'nope'}: not a capture folder"]
    assert not out.exists()
