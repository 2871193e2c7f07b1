"""bench/ablation.py: run names shared across groups, per-variant means over seeds and
paired differences against the reference from the same seeds and images."""

import importlib.util
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def _load():
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
