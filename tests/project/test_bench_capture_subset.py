"""bench/capture_subset.py: a few frames of a HumanNeRF-layout capture, linked, whose own
split holds out frames the capture holds out; the capture untouched, OUT never replaced."""

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
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


@pytest.mark.slow  # two training runs and the command line in a subprocess
def test_score_reads_every_training_frame_as_texvocab_eval_does(tmp_path):
    """--score renders the subset's training frames as `texvocab eval` renders them (the
    same PSNR on the frame both score), and scores a run on the whole capture too."""
    from train_cases import SMALLEST_SET

    from texvocab.cli.main import main

    body = default_body()
    cap_dir = write_standin(tmp_path / "subject", body, make_truth(body))
    few = tmp_path / "few"
    bench = _load()
    bench.write_subset(cap_dir, few, 5)
    tiny = ["encoder=small", "field.hidden=16", "field.sdf_layers=1", "field.color_layers=1", *SMALLEST_SET]
    sets = [a for item in tiny for a in ("--set", item)]
    mine, whole = tmp_path / "few_run" / "checkpoint.pt", tmp_path / "whole_run" / "checkpoint.pt"
    for capture, ck in ((few, mine), (cap_dir, whole)):
        assert main(["train", str(capture), "--out", str(ck.parent), "--iterations", "2", *sets]) == 0
    rows = bench.score(few, [mine, whole], "fast")
    for ck in (mine, whole):
        assert rows[str(ck)]["images"] == 4 and np.isfinite(rows[str(ck)]["per_image"]).all()
    assert (
        main(
            ["eval", str(mine), str(few), "--per-set", "1", "--preset", "fast", "--out", str(tmp_path / "ev")]
        )
        == 0
    )
    first = json.loads((tmp_path / "ev" / "metrics.json").read_text())["images"][0]
    assert first["set"] == "training_poses" and first["frame"] == 0
    assert rows[str(mine)]["per_image"][0] == pytest.approx(first["psnr_bbox"], abs=1e-6)
    run = subprocess.run(
        [sys.executable, str(SCRIPT), str(few), "--score", str(mine), str(whole)],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stderr
    means = [rows[str(ck)]["per_image"].mean() for ck in (mine, whole)]
    assert run.stdout.strip().splitlines()[-1] == f"summary: {mine}={means[0]:.4f} {whole}={means[1]:.4f}"
    assert f"| {mine} | 4 |" in run.stdout and "| +0.000 ± 0.000 | 0% |" in run.stdout
