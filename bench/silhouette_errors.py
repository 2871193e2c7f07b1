"""Where a trained avatar's silhouette misses the masks: the rendered opacity against the
mask of held-out frames, read several ways to tell a soft edge, a bias in or out, and an
offset from the shape errors that remain.

    .venv/bin/python bench/silhouette_errors.py CKPT [--frames 4] [--view 0] [--max-shift 5]
        [--split held-out|training]

Per frame (the capture's held-out frames, or with ``--split training`` its training
frames at their recorded poses, spread; rendered with the checkpoint's knobs):

- IoU of opacity > 0.3, 0.5 and 0.7 against the mask (a soft edge moves these apart);
- IoU of opacity > 0.5 against the mask eroded and dilated by 1 and 2 px (a silhouette
  that is too fat or too thin scores better against one of them);
- the best IoU over whole-pixel shifts of the render up to ``--max-shift`` px, and that
  shift (a calibration or pixel-centre offset shows as the same shift in every frame);
- the sub-pixel move of the render that best puts its outline on the mask's, from the
  outline's four sides separately (``edge_dx``, ``edge_dy``; :func:`mask_registration.side_offsets`):
  unlike the whole-pixel search it does not mistake a shape error on one side (a missing
  hood) for an offset, and the render's being fatter or thinner cancels out;
- precision and recall of the rendered silhouette.

The last line printed is ``summary: iou=… iou_soft_spread=… iou_best_shift=… edge_dx=…
edge_dy=… frames=…``
(means over frames).
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
from mask_registration import side_offsets
from scipy import ndimage

from texvocab.pipeline.avatar import load_avatar
from texvocab.pipeline.evaluate import render_view_rgba, spread
from texvocab.pipeline.settings import march_settings


def iou(pred: np.ndarray, mask: np.ndarray) -> float:
    union = (pred | mask).sum()
    return float((pred & mask).sum() / union) if union else float("nan")


def silhouette_row(alpha: np.ndarray, mask: np.ndarray, max_shift: int) -> dict:
    """The readings of the module docstring for one opacity image (H, W) and mask (H, W)."""
    pred = alpha > 0.5
    row = {f"iou@{th}": iou(alpha > th, mask) for th in (0.3, 0.5, 0.7)}
    for k in (-2, -1, 1, 2):
        grown = (ndimage.binary_dilation if k > 0 else ndimage.binary_erosion)(mask, iterations=abs(k))
        row[f"mask{k:+d}px"] = iou(pred, grown)
    best = (row["iou@0.5"], 0, 0)
    for dy in range(-max_shift, max_shift + 1):
        for dx in range(-max_shift, max_shift + 1):
            score = iou(np.roll(pred, (dy, dx), (0, 1)), mask)
            if score > best[0]:
                best = (score, dx, dy)
    row["best_shift_iou"], row["dx"], row["dy"] = best
    sides = side_offsets(alpha, mask)  # where the render's outline lies outward of the mask's
    row["edge_dx"] = (sides["left"] - sides["right"]) / 2
    row["edge_dy"] = (sides["top"] - sides["bottom"]) / 2
    row["precision"] = float((pred & mask).sum() / max(pred.sum(), 1))
    row["recall"] = float((pred & mask).sum() / max(mask.sum(), 1))
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("checkpoint")
    ap.add_argument("--frames", type=int, default=4)
    ap.add_argument("--view", type=int, default=0)
    ap.add_argument("--max-shift", type=int, default=5)
    ap.add_argument(
        "--split",
        choices=("held-out", "training"),
        default="held-out",
        help="which frames: a shape error of the held-out segment shows there only, a learned offset in both",
    )
    args = ap.parse_args(argv)
    avatar = load_avatar(args.checkpoint, progress=False)
    model, cap = avatar.model, avatar.capture
    march = march_settings(avatar.settings)
    pool = range(cap.num_train, cap.num_frames) if args.split == "held-out" else range(cap.num_train)
    frames = spread(list(pool), args.frames)
    print(f"β = {float(model.beta.detach()) * 1000:.2f} mm; view {args.view}; {args.split} frames {frames}\n")
    keys = None
    rows = []
    for t in frames:
        _, alpha, _ = render_view_rgba(model, cap.poses[t], cap.trans[t], cap.cameras[args.view], march)
        row = silhouette_row(alpha, cap.mask(args.view, t), args.max_shift)
        if keys is None:
            keys = list(row)
            print("| frame | " + " | ".join(keys) + " |")
            print("|---|" + "---|" * len(keys))
        rows.append(row)
        print(
            f"| {t} | "
            + " | ".join(
                str(row[k])
                if k in ("dx", "dy")
                else f"{row[k]:+.2f}"
                if k.startswith("edge_")
                else f"{row[k]:.3f}"
                for k in keys
            )
            + " |"
        )
    mean = {k: float(np.mean([r[k] for r in rows])) for k in keys}
    print("| mean | " + " | ".join(f"{mean[k]:.3f}" for k in keys) + " |")
    print(
        f"summary: iou={mean['iou@0.5']:.3f} iou_soft_spread={mean['iou@0.3'] - mean['iou@0.7']:.3f} "
        f"iou_best_shift={mean['best_shift_iou']:.3f} edge_dx={mean['edge_dx']:+.2f} "
        f"edge_dy={mean['edge_dy']:+.2f} frames={len(rows)}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
