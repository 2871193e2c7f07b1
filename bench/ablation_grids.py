"""The ablation bench's pictures (bench/ablation.py): truth | one column per variant, of
the same novel images, whole (side by side) and cropped to each image's fold region."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from texvocab.io.images import contact_sheet, save_png, to_uint8

SET = "novel_poses"  # the set the ablation scores (texvocab.pipeline.split)


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
