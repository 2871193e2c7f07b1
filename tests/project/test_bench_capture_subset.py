"""bench/capture_subset.py: a few frames of a HumanNeRF-layout capture, linked, whose own
split holds out frames the capture holds out; the capture untouched, OUT never replaced."""

import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
from humannerf_cases import make_truth, write_standin

from texvocab.body import default_body
from texvocab.capture import open as open_capture

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "bench" / "capture_subset.py"


def _load():
    spec = importlib.util.spec_from_file_location("bench_capture_subset", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_frames_are_spread_over_each_side_of_the_split():
    bench = _load()
    train, novel = bench.choose(list(range(432)), list(range(432, 540)), 25)
    assert len(train) == 20 and len(novel) == 5
    assert train[0] == 0 and train[-1] >= 400 and np.all(np.diff(train) > 15)
    assert novel[0] == 432 and novel[-1] >= 518


def test_subset_opens_with_its_own_split_and_leaves_the_capture_alone(tmp_path):
    body = default_body()
    cap_dir = write_standin(tmp_path / "subject", body, make_truth(body))
    before = sorted((p.relative_to(cap_dir), p.stat().st_mtime_ns) for p in cap_dir.rglob("*"))
    out = tmp_path / "few"
    run = subprocess.run(
        [sys.executable, str(SCRIPT), str(cap_dir), str(out), "--frames", "5"], capture_output=True, text=True
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip().splitlines()[-1] == f"summary: train=4 held_out=1 out={out}"
    cap, few = open_capture(cap_dir), open_capture(out)
    assert few.num_train == 4 and few.num_frames == 5
    train_ids, novel_ids = few.frame_ids[:4], few.frame_ids[4:]
    assert set(train_ids) <= set(cap.frame_ids[: cap.num_train])
    assert set(novel_ids) <= set(cap.frame_ids[cap.num_train :])
    for k, fid in enumerate(few.frame_ids):
        t = cap.frame_ids.index(fid)
        np.testing.assert_array_equal(few.image(0, k), cap.image(0, t))
        np.testing.assert_allclose(few.poses[k], cap.poses[t])
        assert (out / "images" / f"frame_{fid:06d}.png").is_symlink()
    assert sorted((p.relative_to(cap_dir), p.stat().st_mtime_ns) for p in cap_dir.rglob("*")) == before
    # an existing OUT is refused, left as it was; too many frames is one error line
    again = subprocess.run(
        [sys.executable, str(SCRIPT), str(cap_dir), str(out)], capture_output=True, text=True
    )
    assert (
        again.returncode == 2
        and again.stderr.strip() == f"error: {out}: exists; expected a new folder (nothing is replaced)"
    )
    many = subprocess.run(
        [sys.executable, str(SCRIPT), str(cap_dir), str(tmp_path / "many"), "--frames", "40"],
        capture_output=True,
        text=True,
    )
    assert many.returncode == 2 and many.stderr.startswith("error: --frames 40: needs 32 training")
    assert not (tmp_path / "many").exists() and len(many.stderr.strip().splitlines()) == 1
