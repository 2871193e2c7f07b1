"""Ablations on novel poses, resumable and in parallel: named variants of the training
settings, each trained once per seed for the same number of steps on the same capture and
evaluated on the same held-out views and novel frames; reported as means over seeds with
their spread and as *paired* differences against a reference variant.

    .venv/bin/python bench/ablation.py GROUP [GROUP ...] [--seeds 0 1 2] [--iterations 500]
        [--jobs 2] [--per-set 10] [--preset fast] [--base KEY=VALUE ...] [--report-only]
        [--garment painted|hoodie|wide-trousers|loose]

Groups (each varies one knob from the common base; the first variant is its reference):
``strategies`` (part/joint/global/none, Table 4 of the paper), ``encoders`` (pyramid,
small, inception, resnet34-scratch), ``perceptual`` (off, inception; lpips-vgg only when its
weights exist), ``weighting`` (paper, inverse), ``views`` (texture maps: mean, cosine),
``keys`` (M = 20, 5, 10, 40, every training frame with Eq. 6's or 1/d weights; K = 3, 1,
5; adaptive M), ``unseen`` (unseen texels: mean,
nearest), ``view_frame`` (γ(d) in the world or the body's frame), ``mask`` (λ_m 0.1, 0.5),
``beta`` (VolSDF β at the start of training: 5, 2 mm), ``texture`` (texture maps of
256² or 512² texels), ``lr`` (the learning rate constant, or decayed to 0.1 of it over
the run), ``shell`` (the base's shell, or 8 cm wide), ``coverage`` (the shell fitted to 97 % or 99 % of
the training masks' pixels),
``refinement`` (pose refinement: off, root, joints), ``training`` (train_guide: shell,
raster; its report adds the training PSNR curve per 100 steps, paired by seed). The base
is ``--base`` on top of the defaults (by default ``encoder=pyramid perceptual=off
weighting=paper view_weighting=mean train_guide=shell train_coarse_samples=none
field.shell_coverage=none train_residual=off train_band_newton=false
train_shell_voxel=0.01``: the project before this ablation chose its defaults; the fixed
shell keeps older runs' folders meaning what they did), so a variant differs from its
reference in exactly its own setting; identical settings share one run. ``train_marcher``
(train_coarse_samples 18, 9) is run with ``--base ... train_guide=raster`` (keeping the
three training-ray items above), ``train_rays``
(marched, residual rays, residual rays and Newton band rays) with ``--base`` and no
items (today's defaults). To add seeds to a group run when training took the evaluation
preset's knobs, pass ``--train-with-preset`` (those runs trained at the evaluation
preset's marcher knobs).

Without CAPTURE a compositional synthetic capture is made under OUT (``texvocab synth
--motion compositional``): its novel frames put part poses seen in training into
whole-body combinations never seen. Each run lives in OUT/runs/<settings>/seed<S>/ with
its checkpoint and result.json; finished runs are skipped, unfinished ones resume.
``--jobs N`` trains N runs at once, each on one thread. Writes OUT/<groups>.md (tables)
and OUT/<group>_side_by_side.png (truth | one column per variant, first seed).
``--garment NAME`` dresses the synthesised person (``texvocab synth --garment``; its
capture is OUT/capture_compositional_NAME). On a capture with fold regions (the pixels
whose truth changes with pose, which ``texvocab synth`` stores) the tables add psnr_fold /
ssim_fold, and OUT/<group>_fold_crops.png crops each grid image around its fold region:
truth | one column per variant (first seed).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from ablation_grids import SET, fold_box, fold_crops, side_by_side  # noqa: F401 (fold_box: tests)
from ablation_tables import FOLD_METRICS, METRICS, group_report

from texvocab.io.images import atomic_write_bytes

# the earlier training rays (marched rest, 5-sample band, shell grid voxel 1 cm)
EARLIER_RAYS = ["train_residual=off", "train_band_newton=false", "train_shell_voxel=0.01"]
DEFAULT_BASE = [
    "encoder=pyramid",
    "perceptual=off",
    "weighting=paper",
    "view_weighting=mean",
    "train_guide=shell",
    "train_coarse_samples=none",
    "field.shell_coverage=none",  # the fixed 4 cm shell runs had before the shell fit
] + EARLIER_RAYS
# base settings that name no run folder: every run before the setting existed had them
UNNAMED = {"train_guide=shell", "train_coarse_samples=none", "field.shell_coverage=none"} | set(EARLIER_RAYS)
GROUPS: dict[str, dict[str, list[str]]] = {
    "strategies": {
        "part": [],
        "joint": ["strategy=joint"],
        "global": ["strategy=global"],
        "none": ["strategy=none"],
    },
    "encoders": {
        "pyramid": [],
        "small": ["encoder=small"],
        "inception": ["encoder=inception"],
        "resnet34-scratch": ["encoder=resnet34-scratch"],
    },
    "perceptual": {"off": [], "inception": ["perceptual=inception"], "lpips-vgg": ["perceptual=lpips-vgg"]},
    "weighting": {"paper": [], "inverse": ["weighting=inverse"]},
    "views": {"mean": [], "cosine": ["view_weighting=cosine"]},
    # texels a frame's views did not see (one-camera captures): the training frames' mean
    # (the default, the reference) against the earlier nearest-seen colour of the same map
    "unseen": {"mean": [], "nearest": ["unseen_texels=nearest"]},
    "view_frame": {"world": [], "body": ["field.view_frame=body"]},
    "mask": {"λ_m 0.1": [], "λ_m 0.5": ["lambda_mask=0.5"]},
    "beta": {"β₀ 5 mm": [], "β₀ 2 mm": ["field.beta_init=0.002"]},
    # texels per side of the texture maps (the pyramid's finest level is half of it)
    "texture": {"256 texels": [], "512 texels": ["texture_size=512"]},
    "lr": {"constant": [], "decay to 0.1": ["lr_decay=0.1"]},
    "beta_lr": {"β at the rate": [], "β at 10× the rate": ["beta_lr_scale=10"]},
    "shell": {"base shell": [], "8 cm": ["field.shell_width=0.08"], "12 cm": ["field.shell_width=0.12"]},
    # the shell fitted to reach 97 % of the training masks' pixels (the default) or 99 %
    "coverage": {"97 % of the masks": [], "99 % of the masks": ["field.shell_coverage=0.99"]},
    # how x_c enters the SDF network: γ(x_c), or γ(x_c) and learned planes over the body
    "position": {"tri-planes": [], "γ(x_c) alone": ["field.position_encoding=frequencies"]},
    # the shell fitted to the masks with one width, or one per body part
    "shell_shape": {"one width": [], "per part": ["field.shell_shape=joints"]},
    # finer position detail for cloth whose folds are geometry: twice the tri-planes' texels
    # a side, or two more octaves of γ(x_c) (finest period 1.5 cm instead of 6)
    "detail": {
        "tri-planes 256, 6 frequencies": [],
        "tri-planes 512": ["field.triplane_resolution=512"],
        "8 frequencies": ["field.pos_freqs=8"],
    },
    # the body's surface as fitted, or moved out to the training masks (clothes off the body)
    "girth": {"body as fitted": [], "girth from the masks": ["data.body_girth=masks"]},
    "refinement": {"off": [], "root": ["pose_refinement=root"], "joints": ["pose_refinement=joints"]},
    "training": {"shell": [], "raster": ["train_guide=raster"]},
    # the shell marcher's coarse step for the rays training still marches (run with
    # --base ... train_guide=raster)
    "train_marcher": {"coarse 18": [], "coarse 9": ["train_coarse_samples=9"]},
    # the rays training does not band: marched, or residual rays inside the mask (hits) or
    # everywhere (all); band rays of 5 samples, or from the probe and the Newton point
    # (run with --base and no items: today's defaults, the reference; the
    # others at the earlier shell grid voxel, 1 cm)
    "train_rays": {"defaults (newton band, residual hits, shell voxel 0.015)": []}
    | {
        k: v + ["train_shell_voxel=0.01"]
        for k, v in {
            "marched (the earlier default)": ["train_residual=off", "train_band_newton=false"],
            "newton band": ["train_residual=off"],
            "newton band, residual hits": ["train_residual=hits"],
            "newton band, residual all": ["train_residual=all"],
            "5-sample band, residual all": ["train_residual=all", "train_band_newton=false"],
        }.items()
    },
    "keys": {
        "M20 K3": [],
        "M5": ["num_keys=5"],
        "M10": ["num_keys=10"],
        "M40": ["num_keys=40"],
        "K1": ["k=1"],
        "K5": ["k=5"],
        "adaptive": ["min_key_distance=0.05"],
        # M = T: a key per training frame, its weights by Eq. 6 or by 1/d (its own map alone)
        "every frame": ["num_keys=0"],
        "every frame, 1/d": ["num_keys=0", "weighting=inverse"],
    },
}


def die_with_parent() -> None:
    """Pool initializer: on Linux, ask the kernel to end this worker when the process that
    started it dies (``prctl(PR_SET_PDEATHSIG, SIGTERM)``), so a killed bench leaves no
    training workers behind. Elsewhere it does nothing."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes
    import signal

    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(1, int(signal.SIGTERM), 0, 0, 0) != 0:  # 1 = PR_SET_PDEATHSIG
        print(f"warning: worker {os.getpid()} will outlive a killed bench", file=sys.stderr)


def make_capture(out: Path, motion: str = "compositional", garment: str = "painted") -> Path:
    """The synthetic capture of ``motion`` under OUT, its person wearing ``garment``
    (``texvocab synth --garment``; reused when present): OUT/capture_<motion> for the
    painted default, OUT/capture_<motion>_<garment> for the others."""
    from texvocab.body import load_body
    from texvocab.capture.garment_sets import garment_spec
    from texvocab.capture.synth import SynthSettings, synthesize

    garment_spec(garment)  # AssetError for an unknown name, before anything is made
    root = out / (f"capture_{motion}" if garment == "painted" else f"capture_{motion}_{garment}")
    if not root.exists():
        if motion == "compositional":
            from texvocab.capture.compositional import compositional_motion as make
        else:
            from texvocab.capture.motion import default_motion as make
        poses, trans, num_train = make(0)
        synthesize(root, poses, trans, num_train, load_body(None), SynthSettings(garment=garment))
    return root


def run_name(base: list[str], extra: list[str]) -> str:
    """Folder name of a run: its settings beyond the defaults, sorted (shared by groups)."""
    items = dict(i.split("=", 1) for i in [b for b in base if b not in UNNAMED] + extra)
    return ",".join(f"{k}={v}" for k, v in sorted(items.items())) or "defaults"


def _steps_done(run_dir: Path) -> int:
    """The steps a run folder holds (its result, else its checkpoint; 0: none)."""
    result, ck = run_dir / "result.json", run_dir / "checkpoint.pt"
    if result.is_file():
        return int(json.loads(result.read_text())["steps"])
    if ck.is_file():
        from texvocab.io.checkpoint import load_checkpoint

        return int(load_checkpoint(ck)["step"])
    return 0


def run_settings(job: dict):
    """(training settings, evaluation settings) of a job: the run's overrides and seed; the
    evaluation also takes the preset's render knobs. Training once took them
    too (its marched rays at the fast preset's coarse 6, fine 2, early stop 1e-2); jobs
    with ``train_with_preset`` still do, to extend the groups run then comparably."""
    from texvocab.pipeline.settings import Settings, TrainSettings, preset_overrides, render_overrides

    pre = preset_overrides(job["preset"], render_only=True) if job["preset"] else []
    trained = Settings(train=TrainSettings(iterations=job["iterations"])).with_overrides(
        (pre if job.get("train_with_preset") else []) + job["overrides"] + [f"seed={job['seed']}"]
    )
    return trained, render_overrides(trained, job["preset"], [])


def train_and_evaluate(job: dict) -> dict:
    """Train (or resume) one run and evaluate it on the novel-pose set; cached in
    result.json. ``job``: root, run_dir, overrides, seed, iterations, per_set, preset,
    grid_rows, threads."""
    import torch

    from texvocab.blas import budget_blas_threads
    from texvocab.capture import open as open_capture
    from texvocab.pipeline.evaluate import build_sets, evaluate_sets, write_report
    from texvocab.pipeline.settings import march_settings, render_overrides
    from texvocab.pipeline.train import Trainer

    run_dir = Path(job["run_dir"])
    done = run_dir / "result.json"
    if done.is_file():
        result = json.loads(done.read_text())
        if result["steps"] == job["iterations"]:
            return _with_metrics(result, run_dir)
    torch.set_num_threads(job["threads"])
    budget_blas_threads(1)  # as the texvocab command does (texvocab/blas.py)
    cap = open_capture(job["root"])
    trainer = Trainer(cap, run_settings(job)[0], run_dir, progress=False)
    trainer.resume()
    # the run's own settings: its field's shell is the one fitted to the masks
    # (field.shell_coverage), which the preset's marcher shell is a share of
    settings = trainer.s
    shown = render_overrides(settings, job["preset"], [])
    t0 = time.perf_counter()
    steps0 = trainer.step
    logs = trainer.run()
    # None when this call trained no step (a finished run evaluated again): not measured
    step_s = (time.perf_counter() - t0) / (trainer.step - steps0) if trainer.step > steps0 else None
    trainer.model.eval()
    sets = {SET: build_sets(cap, settings, job["per_set"], generated=())[SET]}
    table, records, grids = evaluate_sets(
        trainer.model, sets, march_settings(shown), grid_rows=job["grid_rows"], progress=False
    )
    write_report(
        run_dir / "eval",
        table,
        records,
        grids,
        {
            "checkpoint": str(trainer.checkpoint_path),
            "step": trainer.step,
            "capture": str(job["root"]),
            "settings": shown.to_dict(),
        },
    )
    rows = grids[SET]
    images = [r for r in records if r["set"] == SET]
    # grid rows are the set's first images: their frame and view (fold-crop grid)
    np.savez_compressed(
        run_dir / "grid.npz",
        truth=np.stack([r[0] for r in rows]),
        render=np.stack([r[1] for r in rows]),
        frame=np.asarray([r["frame"] for r in images[: len(rows)]], np.int64),
        view=np.asarray([r["view"] for r in images[: len(rows)]], np.int64),
    )
    result = {
        "run": run_dir.parent.name,
        "seed": job["seed"],
        "steps": trainer.step,
        "seconds_per_step": step_s,
        "threads": job["threads"],
        "kid": table[SET].get("kid"),
        # training PSNR of each step's batch (this session's steps; resumed runs
        # have only the steps after the resume)
        "train_psnr": [r["psnr"] for r in logs] if steps0 == 0 else None,
        "per_image": {m: [r.get(m) for r in images] for m in METRICS + FOLD_METRICS},
    }
    blob = json.dumps(result)
    atomic_write_bytes(done, lambda t: Path(t).write_text(blob))
    print(
        f"{run_dir}: {trainer.step} steps, "
        + ("" if step_s is None else f"{step_s:.2f} s/step, ")
        + f"PSNR {table[SET]['psnr_bbox']:.2f} dB",
        flush=True,
    )
    return result


def _with_metrics(result: dict, run_dir: Path) -> dict:
    """A cached result with any METRICS or FOLD_METRICS it predates read back from its
    eval/metrics.json (None per image where that report lacks them too: n/a)."""
    missing = [m for m in METRICS + FOLD_METRICS if m not in result["per_image"]]
    report = run_dir / "eval" / "metrics.json"
    if missing and report.is_file():
        images = [r for r in json.loads(report.read_text())["images"] if r["set"] == SET]
        result["per_image"].update({m: [r.get(m) for r in images] for m in missing})
    return result


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("groups", nargs="+", choices=list(GROUPS))
    ap.add_argument("--capture", default=None, help="capture folder (default: synthesise)")
    ap.add_argument(
        "--garment",
        default="painted",
        help="what the synthesised capture's person wears (texvocab synth --garment: painted, "
        "hoodie, wide-trousers, loose); its own folder OUT/capture_compositional_<garment>",
    )
    ap.add_argument("--iterations", type=int, default=500, help="training steps per run")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument(
        "--only",
        nargs="+",
        default=None,
        metavar="VARIANT",
        help="run only these variants of the groups (the reference is always run)",
    )
    ap.add_argument(
        "--per-set", type=int, default=10, help="novel frames evaluated (x every evaluation view); 0: all"
    )
    ap.add_argument("--grid-rows", type=int, default=3)
    ap.add_argument("--preset", choices=("fast", "balanced", "quality"), default="fast")
    ap.add_argument("--jobs", type=int, default=1, help="runs trained at once (1 thread each when > 1)")
    ap.add_argument("--base", nargs="*", default=DEFAULT_BASE, metavar="KEY=VALUE")
    ap.add_argument("--out", default="out/bench/ablation")
    ap.add_argument("--report-only", action="store_true", help="tables from finished runs")
    ap.add_argument(
        "--train-with-preset",
        action="store_true",
        help="train with the preset's render knobs too, as earlier runs "
        "did (to add seeds to their groups comparably)",
    )
    args = ap.parse_args(argv)
    out = Path(args.out)
    root = Path(args.capture) if args.capture else make_capture(out, garment=args.garment)
    plan: dict[str, dict[str, str]] = {}
    jobs, seen = [], set()
    for g in args.groups:
        ref = next(iter(GROUPS[g]))
        plan[g] = {
            lab: run_name(args.base, extra)
            for lab, extra in GROUPS[g].items()
            if args.only is None or lab in args.only or lab == ref
        }
        for lab, extra in GROUPS[g].items():
            run = plan[g].get(lab)
            for seed in args.seeds:
                if run is None or (run, seed) in seen:
                    continue
                seen.add((run, seed))
                jobs.append(
                    {
                        "root": str(root),
                        "run_dir": str(out / "runs" / run / f"seed{seed}"),
                        "overrides": args.base + extra,
                        "seed": seed,
                        "iterations": args.iterations,
                        "per_set": args.per_set or None,
                        "preset": args.preset,
                        "grid_rows": args.grid_rows,
                        "train_with_preset": args.train_with_preset,
                        "threads": 1 if args.jobs > 1 else 2,
                    }
                )
    jobs.sort(key=lambda j: j["seed"])  # every variant's first seed before any second one
    for j in [] if args.report_only else jobs:
        held = _steps_done(Path(j["run_dir"]))
        if held > args.iterations:
            sys.exit(
                f"error: {j['run_dir']} holds a run of {held} steps, more than --iterations "
                f"{args.iterations}: it would be scored as a run of {args.iterations}; use another "
                "--out (groups share their runs in one --out)"
            )
    if args.report_only:
        results = {}
        for j in jobs:
            f = Path(j["run_dir"]) / "result.json"
            if f.is_file():
                results[(Path(j["run_dir"]).parent.name, j["seed"])] = _with_metrics(
                    json.loads(f.read_text()), f.parent
                )
    else:
        # spawn, not fork: a worker forked after the capture's synthesis (pyrender, torch
        # threads) hung without using any CPU
        with ProcessPoolExecutor(
            args.jobs, mp_context=multiprocessing.get_context("spawn"), initializer=die_with_parent
        ) as pool:
            done = list(pool.map(train_and_evaluate, jobs))
        results = {(r["run"], r["seed"]): r for r in done}
    lines = [
        f"# Ablations on novel poses ({root}; base: {' '.join(args.base) or 'defaults'}; "
        f"preset {args.preset})",
        "",
    ]
    for g in args.groups:
        lines += group_report(g, plan[g], results)
        side_by_side(g, plan[g], args.seeds[0], out)
        fold_crops(g, plan[g], args.seeds[0], out, root)
    md = "\n".join(lines)
    atomic_write_bytes(out / f"{'_'.join(args.groups)}.md", lambda t: Path(t).write_text(md))
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
