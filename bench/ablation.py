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
``keys`` (M = 20, 5, 10, 40; K = 3, 1, 5; adaptive M), ``unseen`` (unseen texels: mean,
nearest), ``view_frame`` (γ(d) in the world or the body's frame), ``mask`` (λ_m 0.1, 0.5),
``beta`` (VolSDF β at the start of training: 5, 2 mm),
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

from texvocab.io.images import atomic_write_bytes, contact_sheet, save_png, to_uint8

METRICS = ("psnr_bbox", "ssim_bbox", "lpips", "iou")  # iou: rendered silhouette (opacity > 0.5)
# on the pixels whose truth changes with pose (texvocab.metrics.fold_region): None for an
# image without a fold region (or a capture without fold_regions.npz)
# psnr_fold_drawn / fold_empty: on the region's pixels the render covers (each run its own
# pixels), and the share it leaves empty (texvocab.metrics.fold_region)
FOLD_METRICS = ("psnr_fold", "ssim_fold", "psnr_fold_drawn", "fold_empty")
SET = "novel_poses"
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
    from texvocab.pipeline.settings import march_settings
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
    settings, shown = run_settings(job)
    trainer = Trainer(cap, settings, run_dir, progress=False)
    trainer.resume()
    t0 = time.perf_counter()
    steps0 = trainer.step
    logs = trainer.run()
    step_s = (time.perf_counter() - t0) / max(1, trainer.step - steps0)
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
            "settings": settings.to_dict(),
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
        f"{run_dir}: {trainer.step} steps, {step_s:.2f} s/step, PSNR {table[SET]['psnr_bbox']:.2f} dB",
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


def _mean(v) -> float | None:
    return None if not v or any(x is None for x in v) else float(np.mean(v))


def _mean_present(v) -> float | None:
    """Mean over the images that have the value (a fold metric: those with a region)."""
    kept = [x for x in v or () if x is not None]
    return float(np.mean(kept)) if kept else None


def _fold_pairs(results: dict, variants: dict[str, str], lab: str, ref: str, seed: int, metric: str):
    """Per-image ``metric`` of variant ``lab`` minus ``ref`` (runs of ``seed``) over the
    images that have it in both runs (a fold metric: those with a fold region)."""
    a, b = (results[(variants[k], seed)]["per_image"].get(metric) for k in (lab, ref))
    if a is None or b is None:  # a run that predates the metric
        return np.zeros(0)
    return np.asarray([x - y for x, y in zip(a, b, strict=True) if x is not None and y is not None], float)


def group_report(group: str, variants: dict[str, str], results: dict) -> list[str]:
    """Markdown of one group: ``variants`` maps a label to its run name (the first is the
    reference); ``results[(run, seed)]`` are result dicts."""
    labels = [v for v in variants if any(k[0] == variants[v] for k in results)]
    if not labels:
        return []
    seeds = sorted({k[1] for k in results})
    by = {
        (lab, s): {m: _mean(results[(variants[lab], s)]["per_image"].get(m)) for m in METRICS}
        | {m: _mean_present(results[(variants[lab], s)]["per_image"].get(m)) for m in FOLD_METRICS}
        | {
            "kid": results[(variants[lab], s)].get("kid"),
            "sps": results[(variants[lab], s)]["seconds_per_step"],
        }
        for lab in labels
        for s in seeds
        if (variants[lab], s) in results
    }
    first = results[next(k for k in results if k[0] == variants[labels[0]])]
    steps, n_img = first["steps"], len(first["per_image"]["psnr_bbox"])
    n_fold = sum(x is not None for x in first["per_image"].get("psnr_fold") or ())
    cols = METRICS + FOLD_METRICS + ("kid", "sps")
    lines = [
        f"## {group}: {steps} steps per run, seeds {', '.join(map(str, seeds))}; "
        f"{n_img} novel-pose images per run, {n_fold} with a fold region",
        "",
        "Mean over seeds of each run's mean (spread over seeds = max - min); `kid` over "
        "the run's images against the truth; `sps` = training seconds per step; "
        "`psnr_fold` / `ssim_fold`: on the pixels whose truth changes with pose "
        "(texvocab.metrics.fold_region), the mean over the run's images that have a fold "
        "region (n/a: none has one, or the run predates the metric); `psnr_fold_drawn` on "
        "the region's pixels the render covers (opacity > 0.5, each run its own pixels), "
        "`fold_empty` the share of the region it leaves empty.",
        "",
        "| variant | " + " | ".join(cols) + " | per seed PSNR |",
        "|---" * (len(cols) + 2) + "|",
    ]
    for lab in labels:
        cells = []
        for m in cols:
            v = [by[(lab, s)][m] for s in seeds if (lab, s) in by]
            cells.append(
                "n/a" if not v or any(x is None for x in v) else f"{np.mean(v):.4f} ({max(v) - min(v):.4f})"
            )
        per_seed = ", ".join(f"{by[(lab, s)]['psnr_bbox']:.2f}" for s in seeds if (lab, s) in by)
        lines.append(f"| {lab} | " + " | ".join(cells) + f" | {per_seed} |")
    ref = labels[0]
    others = labels[1:]
    if others and len(seeds) > 1:
        lines += [
            "",
            f"Paired, other - {ref} (same seed, same images): mean [min, max] over "
            "seeds (the fold metrics over the images with a fold region in both runs); "
            "then per image over all seeds, on the whole image (bbox) and on the fold "
            "regions: mean ± standard error (n = image pairs) and the share of pairs where "
            "the other is better. A range containing 0 is not resolved.",
            "",
            f"| other - {ref} | "
            + " | ".join(METRICS + FOLD_METRICS)
            + " | d PSNR per image | better | d PSNR fold per image | better (fold) |",
            "|---" * (len(METRICS) + len(FOLD_METRICS) + 5) + "|",
        ]
        for lab in others:
            pairs = [s for s in seeds if (lab, s) in by and (ref, s) in by]
            cells = []
            for m in METRICS:
                d = [
                    by[(lab, s)][m] - by[(ref, s)][m]
                    for s in pairs
                    if by[(lab, s)][m] is not None and by[(ref, s)][m] is not None
                ]
                cells.append("n/a" if not d else f"{np.mean(d):+.4f} [{min(d):+.4f}, {max(d):+.4f}]")
            for m in FOLD_METRICS:
                d = [
                    float(f.mean())
                    for f in (_fold_pairs(results, variants, lab, ref, s, m) for s in pairs)
                    if len(f)
                ]
                cells.append("n/a" if not d else f"{np.mean(d):+.4f} [{min(d):+.4f}, {max(d):+.4f}]")
            d = (
                np.concatenate(
                    [
                        np.subtract(
                            results[(variants[lab], s)]["per_image"]["psnr_bbox"],
                            results[(variants[ref], s)]["per_image"]["psnr_bbox"],
                        )
                        for s in pairs
                    ]
                )
                if pairs
                else np.zeros(0)
            )
            img = (
                f"{d.mean():+.3f} ± {d.std(ddof=1) / np.sqrt(len(d)):.3f} (n = {len(d)})"
                if len(d) > 1
                else "n/a"
            )
            better = f"{(d > 0).mean():.0%}" if len(d) else "n/a"
            f = np.concatenate(
                [np.zeros(0)] + [_fold_pairs(results, variants, lab, ref, s, "psnr_fold") for s in pairs]
            )
            fold = (
                f"{f.mean():+.3f} ± {f.std(ddof=1) / np.sqrt(len(f)):.3f} (n = {len(f)})"
                if len(f) > 1
                else "n/a"
            )
            fold_better = f"{(f > 0).mean():.0%}" if len(f) else "n/a"
            lines.append(
                f"| {lab} | " + " | ".join(cells) + f" | {img} | {better} | {fold} | {fold_better} |"
            )
    return lines + curve_report(labels, variants, results, seeds) + [""]


def curve_report(
    labels: list[str], variants: dict[str, str], results: dict, seeds: list[int], window: int = 100
) -> list[str]:
    """Markdown table of the training PSNR (each step's batch) per window of ``window``
    steps: per variant the mean over seeds (spread = max - min over seeds), and each
    variant minus the reference, paired by seed (mean [min, max]). Empty unless every run
    of the group recorded its curve."""
    curves = {
        (lab, s): results[(variants[lab], s)].get("train_psnr")
        for lab in labels
        for s in seeds
        if (variants[lab], s) in results
    }
    if not curves or any(c is None for c in curves.values()):
        return []
    n = min(len(c) for c in curves.values())
    edges = list(range(0, n, window))
    win = {k: [float(np.mean(c[a : a + window])) for a in edges] for k, c in curves.items()}
    ref = labels[0]
    lines = [
        "",
        f"Training PSNR (dB, each step's batch) per {window} steps: mean over seeds "
        f"(spread); then minus {ref}, paired by seed: mean [min, max].",
        "",
        "| variant | " + " | ".join(f"{a}-{min(a + window, n)}" for a in edges) + " |",
        "|---" * (len(edges) + 1) + "|",
    ]
    for lab in labels:
        cells = []
        for i in range(len(edges)):
            v = [win[(lab, s)][i] for s in seeds if (lab, s) in win]
            cells.append(f"{np.mean(v):.2f} ({max(v) - min(v):.2f})")
        lines.append(f"| {lab} | " + " | ".join(cells) + " |")
    for lab in labels[1:]:
        cells = []
        for i in range(len(edges)):
            d = [win[(lab, s)][i] - win[(ref, s)][i] for s in seeds if (lab, s) in win and (ref, s) in win]
            cells.append(f"{np.mean(d):+.2f} [{min(d):+.2f}, {max(d):+.2f}]" if d else "n/a")
        lines.append(f"| {lab} - {ref} | " + " | ".join(cells) + " |")
    return lines


def side_by_side(group: str, variants: dict[str, str], seed: int, out: Path) -> Path | None:
    """truth | one column per variant (its ``seed`` run), the same novel images."""
    grids = {lab: out / "runs" / run / f"seed{seed}" / "grid.npz" for lab, run in variants.items()}
    grids = {lab: np.load(p) for lab, p in grids.items() if p.is_file()}
    if not grids:
        return None
    truth = next(iter(grids.values()))["truth"]
    rows = [[truth[i]] + [g["render"][i] for g in grids.values()] for i in range(len(truth))]
    return save_png(
        out / f"{group}_side_by_side.png",
        contact_sheet(rows, col_labels=["truth"] + [f"{lab} (seed {seed})" for lab in grids]),
    )


def _grid_rows_where(run_dir: Path, grid) -> list[tuple[int, int]] | None:
    """(frame, view) of each row of a run's grid.npz: stored with it, or (grids written
    before they were) the first images of its eval/metrics.json, whose order the grid
    rows follow."""
    if "frame" in grid and "view" in grid:
        return list(zip(grid["frame"].tolist(), grid["view"].tolist(), strict=True))
    report = run_dir / "eval" / "metrics.json"
    if not report.is_file():
        return None
    images = [r for r in json.loads(report.read_text())["images"] if r["set"] == SET]
    if len(images) < len(grid["truth"]) or any("frame" not in r for r in images):
        return None
    return [(r["frame"], r["view"]) for r in images[: len(grid["truth"])]]


def fold_box(region: np.ndarray, margin: int = 8) -> tuple[int, int, int, int]:
    """(y0, y1, x0, x1): a square around the bounding box of the bool ``region``, ``margin``
    pixels wider on each side, kept inside the image (smaller when the image is)."""
    h, w = region.shape
    ys, xs = np.nonzero(region)
    cy, cx = (ys.min() + ys.max() + 1) / 2, (xs.min() + xs.max() + 1) / 2
    side = min(h, w, max(ys.max() - ys.min(), xs.max() - xs.min()) + 1 + 2 * margin)
    y0 = int(np.clip(round(cy - side / 2), 0, h - side))
    x0 = int(np.clip(round(cx - side / 2), 0, w - side))
    return y0, y0 + side, x0, x0 + side


def fold_crops(
    group: str, variants: dict[str, str], seed: int, out: Path, root: Path, tile: int | None = None
) -> Path | None:
    """OUT/<group>_fold_crops.png: per grid image (first ``seed``) with a fold region, a
    crop around the region's bounding box (a margin around it, squared, scaled to
    ``tile`` pixels by nearest neighbour; by default the largest crop's side, so that no
    crop is shrunk): truth | one column per variant. None when the capture stores no fold
    regions or no variant has a grid."""
    from PIL import Image

    from texvocab.capture.fold_regions import FoldRegions

    folds = FoldRegions.load(root)
    if folds is None:
        return None
    grids = {}
    for lab, run in variants.items():
        run_dir = out / "runs" / run / f"seed{seed}"
        if (run_dir / "grid.npz").is_file():
            g = dict(np.load(run_dir / "grid.npz"))
            where = _grid_rows_where(run_dir, g)
            if where is not None:
                grids[lab] = (g, where)
    if not grids:
        return None
    truth, where = next(iter(grids.values()))
    truth = truth["truth"]
    n = min(len(w) for _, w in grids.values())

    shown, labels = [], []
    for i in range(n):
        if any(w[i] != where[i] for _, w in grids.values()):
            continue  # runs whose grids show other images
        region = folds.region(*where[i])
        if region is None or not region.any() or region.shape != truth[i].shape[:2]:
            continue
        shown.append((i, fold_box(region)))
        labels.append(f"frame {where[i][0]} view {where[i][1]}")
    if not shown:
        return None
    tile = tile or max(b[1] - b[0] for _, b in shown)

    def scaled(img: np.ndarray, box) -> np.ndarray:
        y0, y1, x0, x1 = box
        crop = Image.fromarray(np.ascontiguousarray(to_uint8(img[y0:y1, x0:x1, :3])))
        return np.asarray(crop.resize((tile, tile), Image.NEAREST))

    rows = [
        [scaled(truth[i], box)] + [scaled(g["render"][i], box) for g, _ in grids.values()] for i, box in shown
    ]
    return save_png(
        out / f"{group}_fold_crops.png",
        contact_sheet(
            rows, row_labels=labels, col_labels=["truth"] + [f"{lab} (seed {seed})" for lab in grids]
        ),
    )


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
