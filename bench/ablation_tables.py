"""The ablation bench's tables (bench/ablation.py): per group, the mean over seeds of each
run's metrics with their spread, the paired differences against the reference variant (per
seed and per image), fold-region metrics over the images that have a region, and the
training PSNR curve paired by seed."""

from __future__ import annotations

import numpy as np

METRICS = ("psnr_bbox", "ssim_bbox", "lpips", "iou")  # iou: rendered silhouette (opacity > 0.5)
# on the pixels whose truth changes with pose (texvocab.metrics.fold_region): None for an
# image without a fold region (or a capture without fold_regions.npz)
# psnr_fold_drawn / fold_empty: on the region's pixels the render covers (each run its own
# pixels), and the share it leaves empty (texvocab.metrics.fold_region)
FOLD_METRICS = ("psnr_fold", "ssim_fold", "psnr_fold_drawn", "fold_empty")


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
