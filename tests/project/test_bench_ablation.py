"""bench/ablation.py: run names shared across groups, per-variant means over seeds and
paired differences against the reference from the same seeds and images."""

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import torch
from train_cases import SMALLEST_SET

ROOT = Path(__file__).resolve().parents[2]


def _load():
    if str(ROOT / "bench") not in sys.path:  # its sibling modules (ablation_tables, ...)
        sys.path.insert(0, str(ROOT / "bench"))
    spec = importlib.util.spec_from_file_location("bench_ablation", ROOT / "bench" / "ablation.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _result(run, seed, psnr, sps=1.0):
    return {
        "run": run,
        "seed": seed,
        "steps": 7,
        "seconds_per_step": sps,
        "kid": 0.01,
        "per_image": {"psnr_bbox": psnr, "ssim_bbox": [0.5] * len(psnr), "lpips": [None] * len(psnr)},
    }


def test_identical_settings_share_one_run_across_groups():
    bench = _load()
    base = ["encoder=pyramid", "perceptual=off"]
    assert bench.run_name(base, []) == bench.run_name(base, ["encoder=pyramid"])
    assert bench.run_name(base, ["encoder=small"]) == "encoder=small,perceptual=off"
    refs = {next(iter(v.values())) == [] for v in bench.GROUPS.values()}
    assert refs == {True}  # every group's reference is the base itself


def test_report_pairs_seeds_and_images():
    bench = _load()
    runs = {"ref": "a", "other": "b"}
    psnr = {("a", 0): [30.0, 31.0], ("b", 0): [29.0, 29.5], ("a", 1): [28.0, 28.0], ("b", 1): [28.5, 28.5]}
    results = {k: _result(k[0], k[1], v) for k, v in psnr.items()}
    md = "\n".join(bench.group_report("g", runs, results))
    assert "| ref | 29.2500 (2.5000) |" in md  # seed means 30.5 and 28.0
    # paired per seed other - ref: -1.25 (seed 0), +0.5 (seed 1); mean -0.375, straddles 0
    assert "| other | -0.3750 [-1.2500, +0.5000]" in md
    d = np.array([-1.0, -1.5, 0.5, 0.5])
    assert f"{d.mean():+.3f} ± {d.std(ddof=1) / 2:.3f} (n = 4) | 50% |" in md
    assert "7 steps per run, seeds 0, 1; 2 novel-pose images" in md


def test_the_evaluation_preset_does_not_change_training_unless_asked():
    """Runs train with their own settings and are evaluated at the preset's render knobs;
    --train-with-preset trains at the preset's knobs as earlier runs did."""
    mod = _load()
    job = {"preset": "fast", "iterations": 7, "overrides": ["train_coarse_samples=9"], "seed": 3}
    trained, shown = mod.run_settings(job)
    assert (trained.render.coarse_samples, trained.render.fine_samples, trained.train.coarse_samples) == (
        18,
        8,
        9,
    )
    assert (shown.render.coarse_samples, shown.render.fine_samples, shown.train.seed) == (6, 2, 3)
    old, _ = mod.run_settings({**job, "train_with_preset": True})
    assert (old.render.coarse_samples, old.render.fine_samples) == (6, 2)


_ORPHAN_SCRIPT = """
import multiprocessing, os, sys, time
from concurrent.futures import ProcessPoolExecutor
sys.path.insert(0, sys.argv[1])  # the spawned worker inherits the path and imports it too
import ablation

def pid_then_sleep(_):
    print(os.getpid(), flush=True)
    time.sleep(120)

if __name__ == "__main__":
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(1, mp_context=ctx, initializer=ablation.die_with_parent) as pool:
        list(pool.map(pid_then_sleep, [0]))
"""


def test_a_killed_bench_leaves_no_training_worker(tmp_path):
    """The pool's workers end with the bench: SIGKILL on the parent, and the worker that was
    sleeping in a job is gone within seconds."""
    import os
    import signal
    import subprocess
    import sys
    import time

    script = tmp_path / "orphan.py"
    script.write_text(_ORPHAN_SCRIPT)
    parent = subprocess.Popen(
        [sys.executable, str(script), str(ROOT / "bench")],
        stdout=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )
    try:
        worker = int(parent.stdout.readline())
        os.kill(worker, 0)  # alive while the parent is
        parent.kill()
        parent.wait(30)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            try:
                os.kill(worker, 0)
            except ProcessLookupError:
                break
            # a zombie awaiting its reaper counts as gone
            stat = Path(f"/proc/{worker}/stat")
            if stat.is_file() and stat.read_text().split(") ")[1].startswith("Z"):
                break
            time.sleep(0.2)
        else:
            os.kill(worker, signal.SIGKILL)
            raise AssertionError("the worker outlived its killed bench")
    finally:
        parent.kill()


def _fold_result(run, seed, psnr, fold):
    r = _result(run, seed, psnr)
    r["per_image"] |= {"psnr_fold": fold, "ssim_fold": [None if f is None else 0.5 for f in fold]}
    return r


def test_report_scores_fold_regions_over_the_images_that_have_one():
    """Fold metrics: each run's mean over its images with a region; paired per image over
    the images with a region in both runs, with their count; a run from before the metric
    reads n/a."""
    bench = _load()
    runs = {"ref": "a", "other": "b"}
    fold = {
        ("a", 0): [20.0, None, 22.0],
        ("b", 0): [21.0, None, 25.0],
        ("a", 1): [10.0, None, 12.0],
        ("b", 1): [10.5, None, 12.5],
    }
    results = {k: _fold_result(k[0], k[1], [30.0, 30.0, 30.0], v) for k, v in fold.items()}
    md = "\n".join(bench.group_report("g", runs, results))
    assert "3 novel-pose images per run, 2 with a fold region" in md
    # ref: seed means 21 and 11 -> 16 (spread 10); other: 23 and 11.5 -> 17.25 (11.5)
    assert "| ref | 30.0000 (0.0000) | 0.5000 (0.0000) | n/a | n/a | 16.0000 (10.0000) |" in md
    assert "| other | 30.0000 (0.0000) | 0.5000 (0.0000) | n/a | n/a | 17.2500 (11.5000) |" in md
    d = np.array([1.0, 3.0, 0.5, 0.5])  # per image, seeds 0 and 1
    # paired psnr_fold per seed: +2.0 (seed 0), +0.5 (seed 1)
    assert "| +1.2500 [+0.5000, +2.0000] | +0.0000 [+0.0000, +0.0000] |" in md
    assert f"| {d.mean():+.3f} ± {d.std(ddof=1) / 2:.3f} (n = 4) | 100% |" in md
    older = {k: _result(k[0], k[1], [30.0, 30.0, 30.0]) for k in fold}  # no fold metrics
    md = "\n".join(bench.group_report("g", runs, older))
    assert "| ref | 30.0000 (0.0000) | 0.5000 (0.0000) | n/a | n/a | n/a | n/a |" in md
    assert "0 with a fold region" in md and md.count("| n/a | n/a |") >= 3


def test_a_cached_result_reads_its_fold_metrics_from_its_report(tmp_path):
    bench = _load()
    (tmp_path / "eval").mkdir()
    images = [
        {"set": "novel_poses", "psnr_fold": 21.0, "ssim_fold": 0.7},
        {"set": "training_poses", "psnr_fold": 99.0},
        {"set": "novel_poses"},  # no fold region
    ]
    (tmp_path / "eval" / "metrics.json").write_text(json.dumps({"images": images}))
    result = bench._with_metrics(_result("a", 0, [30.0, 29.0]), tmp_path)
    assert result["per_image"]["psnr_fold"] == [21.0, None]
    assert result["per_image"]["ssim_fold"] == [0.7, None]


def test_garment_reaches_the_synthesis_of_its_own_capture(tmp_path, monkeypatch):
    """--garment NAME: the capture is synthesised with that garment, in its own folder
    (the painted default keeps the folder earlier runs used); an unknown name fails
    before anything is made."""
    import pytest

    from texvocab.capture import synth
    from texvocab.errors import TexvocabError

    bench = _load()
    made = {}

    def record(root, poses, trans, num_train, body, settings=None, **kw):
        made[Path(root).name] = settings.garment
        Path(root).mkdir(parents=True)
        return Path(root)

    monkeypatch.setattr(synth, "synthesize", record)  # rendering 102 frames is tested elsewhere
    assert bench.main(["strategies", "--garment", "loose", "--out", str(tmp_path), "--report-only"]) == 0
    bench.make_capture(tmp_path)
    assert made == {"capture_compositional_loose": "loose", "capture_compositional": "painted"}
    with pytest.raises(TexvocabError, match="unknown garment"):
        bench.make_capture(tmp_path, garment="kilt")
    assert sorted(p.name for p in tmp_path.glob("capture_*")) == sorted(made)


def test_fold_crops_show_truth_and_one_column_per_variant(tmp_path):
    """From a tiny real run on a capture with fold regions: the crop grid has a row per
    grid image with a region and truth + one column per variant, each crop centred on
    its image's fold region."""
    import shutil

    from PIL import Image

    from texvocab.body import default_body
    from texvocab.capture.fold_regions import FoldRegions
    from texvocab.capture.motion import make_sequence
    from texvocab.capture.synth import SynthSettings, synthesize

    bench = _load()
    poses, trans = make_sequence([("squat", 3)], seed=0)
    s = SynthSettings(ring_views=3, raised_views=0, size=48, texture_size=128, garment="hoodie")
    cap = synthesize(tmp_path / "cap", poses, trans, 2, default_body(), s, progress=False)
    tiny = [
        *SMALLEST_SET,
        "field.hidden=16",
        "field.sdf_layers=1",
        "field.color_layers=1",
        "field.pos_freqs=2",
        "encoder=small",
        "eval_views=1,2",
        "field.shell_width=0.01",  # narrower than the hoodie: the run widens its shell
    ]
    job = {
        "root": str(cap),
        "run_dir": str(tmp_path / "runs" / "a" / "seed0"),
        "overrides": tiny,
        "seed": 0,
        "iterations": 1,
        "per_set": None,
        "preset": "fast",
        "grid_rows": 3,
        "threads": 1,
    }
    result = bench.train_and_evaluate(job)
    assert result["per_image"]["psnr_fold"][0] is not None  # frame 2, view 1 has a region
    # the evaluation renders with the run's fitted shell (the preset's marcher shell is a
    # share of it), not with the width the run was asked to start from
    run_dir = tmp_path / "runs" / "a" / "seed0"
    fitted = torch.load(run_dir / "checkpoint.pt", weights_only=True)["settings"]["field"]["shell_width"]
    shown = json.loads((run_dir / "eval" / "metrics.json").read_text())["meta"]["settings"]
    assert fitted > 0.01 and shown["field"]["shell_width"] == fitted
    grid = np.load(tmp_path / "runs" / "a" / "seed0" / "grid.npz")
    assert grid["frame"].tolist() == [2, 2] and grid["view"].tolist() == [1, 2]
    shutil.copytree(tmp_path / "runs" / "a", tmp_path / "runs" / "b")
    variants = {"part": "a", "global": "b", "none": "missing"}  # a variant without runs: no column
    png = bench.fold_crops("strategies", variants, 0, tmp_path, cap, tile=40)
    regions = FoldRegions.load(cap)
    rows = sum(bool(regions.region(2, v).any()) for v in (1, 2))
    pad, label_h, left = 4, 16, 90  # texvocab.io.images.contact_sheet
    assert Image.open(png).size == (left + 3 * (40 + pad) + pad, label_h + rows * (40 + pad) + pad)
    box = bench.fold_box(regions.region(2, 1))
    ys, xs = np.nonzero(regions.region(2, 1))
    assert box[0] <= ys.min() and ys.max() < box[1] and box[2] <= xs.min() and xs.max() < box[3]


def test_a_longer_run_in_the_out_folder_is_refused_not_rescored(tmp_path, capsys):
    """A group run with fewer --iterations in an --out whose shared reference run holds more
    steps would score that longer run as the reference: one error line naming it, nothing
    trained, the run's result untouched."""
    import pytest

    bench = _load()
    cap = tmp_path / "cap"
    cap.mkdir()
    run = tmp_path / "out" / "runs" / bench.run_name([], []) / "seed0"
    run.mkdir(parents=True)
    result = run / "result.json"
    result.write_text(json.dumps(_result("defaults", 0, [30.0]) | {"steps": 1000}))
    before = result.read_text()
    argv = ["beta_lr", "--capture", str(cap), "--out", str(tmp_path / "out"), "--seeds", "0"]
    argv += ["--iterations", "600", "--base"]
    with pytest.raises(SystemExit) as exc:
        bench.main(argv)
    message = str(exc.value)
    assert message.startswith("error: ") and str(run) in message and "1000 steps" in message
    assert result.read_text() == before
    assert not (run.parent.parent / "beta_lr_scale=10").exists()
