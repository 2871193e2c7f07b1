"""Training throughput: steps per second of the default training (1024 rays per step) and
what each of the method's optional terms costs, as ratios against a reference measured
in the same run (this machine's speed varies several-fold from day to day).

    .venv/bin/python bench/train_speed.py [CAPTURE] [--steps 30] [--warmup 5] [--threads 2]

Each variant trains ``--warmup`` steps (encoder features and compiled kernels warm up) and
then ``--steps`` timed steps from the same seed. The frozen encoders' feature maps are
computed for every training frame before timing (a one-off cost per run, printed
separately). A step that draws a frame or view for the first time also builds its caches
(pose context, shell, ray bounds, surface plan: a one-off per frame and view, about a
minute over a 72-frame, 8-view capture); the table gives the steps' time with and without
those builds, the steady state of a long run being the latter. Reference:
``encoder=pyramid, perceptual=off, train_guide=shell`` (the project's numbers before the
perceptual term, the encoders and the surface band in training were added). Without
CAPTURE the compositional benchmark capture (bench/ablation.py) is used.

Like the ``texvocab`` command, the bench keeps numpy's BLAS to one thread
(texvocab/blas.py); the second row runs the reference with OpenBLAS's own default (a
thread per core, which spin between calls), as training ran before that change.
"""

from __future__ import annotations

import argparse
import contextlib
import time
from pathlib import Path

import torch
from threadpoolctl import threadpool_limits

from texvocab.blas import blas_threads, budget_blas_threads

# the earlier training rays: the rest marched, 5-sample band, shell voxel 1 cm
EARLIER_RAYS = ["train_residual=off", "train_band_newton=false", "train_shell_voxel=0.01"]
SHELL = ["encoder=pyramid", "perceptual=off", "train_guide=shell", "train_shell_voxel=0.01"]
UNBUDGETED = "reference, numpy's BLAS on every core (before texvocab/blas.py)"
PLAIN_SOFTPLUS = "defaults with torch's nn.Softplus (before NormalSoftplus)"
VARIANTS = {
    "reference (pyramid, no perceptual, shell marcher)": SHELL,
    UNBUDGETED: SHELL,
    "+ inception-perceptual": SHELL[:1] + ["perceptual=inception"] + SHELL[2:],
    "encoder inception (frozen)": ["encoder=inception"] + SHELL[1:],
    "encoder small (trained)": ["encoder=small"] + SHELL[1:],
    "encoder resnet34-scratch": ["encoder=resnet34-scratch"] + SHELL[1:],
    "texture maps cosine-weighted": SHELL + ["view_weighting=cosine"],
    "train_guide raster (surface band)": SHELL[:2]
    + ["train_guide=raster", "train_coarse_samples=none"]
    + EARLIER_RAYS,
    "train_guide raster, train_coarse_samples 9": SHELL[:2]
    + ["train_guide=raster", "train_coarse_samples=9"]
    + EARLIER_RAYS,
    "the earlier defaults (5-sample band, the rest marched)": EARLIER_RAYS,
    "Newton band, the rest marched": ["train_residual=off"],
    "Newton band, residual rays everywhere (train_residual=all)": ["train_residual=all"],
    "defaults at train_shell_voxel 0.01": ["train_shell_voxel=0.01"],
    "defaults (Newton band, residual rays inside the mask)": [],
    PLAIN_SOFTPLUS: [],
    "defaults, eikonal term on 128 points": ["eikonal_points=128"],
    "defaults without the eikonal term": ["lambda_eikonal=0"],
    "defaults without the perceptual term": ["perceptual=off"],
}


def measure(capture, overrides: list[str], steps: int, warmup: int, plain_softplus: bool = False) -> dict:
    from render_timing import plain_softplus as plain  # bench/ sibling

    from texvocab.pipeline.settings import Settings, TrainSettings
    from texvocab.pipeline.train import Trainer

    s = Settings(train=TrainSettings(iterations=steps + warmup)).with_overrides(overrides)
    t0 = time.perf_counter()
    trainer = Trainer(capture, s, Path("/tmp/texvocab_train_speed"), progress=False)
    pf = trainer.model.pose_feature
    if not getattr(pf.encoder, "trainable", True):
        pf.feature_maps(torch.arange(capture.num_train))
    setup = time.perf_counter() - t0
    with plain(trainer.model, plain_softplus):  # the activation has no parameters to optimise
        for _ in range(warmup):
            trainer.train_step()
        t0, cache0 = time.perf_counter(), trainer.cache_seconds
        evals = 0
        for _ in range(steps):
            evals += trainer.train_step()["evals"]
        wall = time.perf_counter() - t0
    per_step = wall / steps
    steady = (wall - (trainer.cache_seconds - cache0)) / steps
    return {
        "setup_s": setup,
        "step_s": per_step,
        "steady_s": steady,
        "evals": evals / steps,
        "encoder": pf.encoder.name,
        "perceptual": getattr(trainer.perceptual, "name", type(trainer.perceptual).__name__)
        if trainer.perceptual is not None
        else "off",
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("capture", nargs="?", default="out/bench/strategies/capture_compositional")
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--only", nargs="*", default=None, help="variant names (substrings)")
    args = ap.parse_args(argv)
    from texvocab.capture import open as open_capture

    torch.set_num_threads(args.threads)
    own_blas = blas_threads()  # OpenBLAS's default: one thread per core
    budget_blas_threads(1)  # as the texvocab command does (texvocab/blas.py)
    cap = open_capture(args.capture)
    rows = []
    for name, overrides in VARIANTS.items():
        if args.only and not any(o in name for o in args.only):
            continue
        blas = (
            threadpool_limits(limits=max(own_blas, 1), user_api="blas")
            if name == UNBUDGETED
            else contextlib.nullcontext()
        )
        with blas:
            r = measure(cap, overrides, args.steps, args.warmup, name == PLAIN_SOFTPLUS)
        rows.append((name, r))
        print(f"{name}: {r['step_s']:.3f} s/step, {r['steady_s']:.3f} without cache builds", flush=True)
    ref, ref_steady = rows[0][1]["step_s"], rows[0][1]["steady_s"]
    print(
        f"\n{args.steps} timed steps each after {args.warmup} warm-up steps, 1024 rays per "
        f"step, {args.threads} threads, capture {args.capture}\n"
    )
    print(
        "| variant | encoder | perceptual | s/step | time ÷ reference | s/step without cache "
        "builds | time ÷ reference | field evals/step | setup s |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name, r in rows:
        print(
            f"| {name} | {r['encoder']} | {r['perceptual']} | {r['step_s']:.3f} | "
            f"{r['step_s'] / ref:.2f} | {r['steady_s']:.3f} | {r['steady_s'] / ref_steady:.2f} "
            f"| {r['evals']:.0f} | {r['setup_s']:.1f} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
