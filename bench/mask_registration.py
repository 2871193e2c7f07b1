"""Where a capture's masks sit against the person's edges in its images: per side of the
silhouette, how far the image's edge lies outward of the mask's, to a quarter pixel.

    .venv/bin/python bench/mask_registration.py CAPTURE [--frames 16] [--view 0] [--body]

Both are read as on disk (a lens distorts image and mask alike, so nothing is undistorted).
With ``--body`` the posed body (fitted to the capture's rest joints) takes the image's
place: its silhouette's pixel coverage (rasterised 4x finer in each direction) against the
mask undistorted as training reads it, moves up to 8 px (clothes stand off the body).
Per frame, the mask's edge (gradient magnitude of the mask blurred by σ 1 px) is moved
along its outward normal in 0.25 px steps, separately on the left-, right-, top- and
bottom-facing parts of the outline, and the move whose edge correlates best with the image's
own edge (gradient magnitude of the grey image, σ 1 px, within 6 px of the outline) is
refined with a parabola. Where the image's outline lies against the mask's, as a common
shift, is ``(right − left) / 2`` and ``(bottom − top) / 2`` (+x right, +y down); a mask
drawn fatter or thinner than the person shows as the mean of opposite sides (negative: the
image's edge lies inside the mask).
Pixels are those on disk; halve them for a capture evaluated at half size.

The last line printed is ``summary: shift_x=… shift_y=… grow_x=… grow_y=… frames=…``
(means over frames, pixels on disk).
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
from scipy import ndimage

from texvocab.capture import open as open_capture
from texvocab.capture.image_reader import read_image, read_mask
from texvocab.geometry.raster import rasterize_mesh

SIDES = ("left", "right", "top", "bottom")
STEP = 0.25


def side_offsets(image: np.ndarray, mask: np.ndarray, reach: float = 4.0) -> dict[str, float]:
    """{side: px} how far the image's edge lies outward of the mask's on each side of the
    outline (negative: inside), for a grey image (H, W) and a bool mask (H, W)."""
    ys, xs = np.nonzero(mask)
    crop = np.s_[max(ys.min() - 12, 0) : ys.max() + 12, max(xs.min() - 12, 0) : xs.max() + 12]
    grey, m = image[crop].astype(np.float64), mask[crop].astype(np.float64)
    g_img = ndimage.gaussian_gradient_magnitude(grey, 1.0)
    gy, gx = np.gradient(ndimage.gaussian_filter(m, 1.0))
    g_mask = np.hypot(gx, gy)
    edge = g_mask > 0.02
    near = ndimage.binary_dilation(edge, iterations=6)
    facing = {  # the outward normal is minus the mask's gradient
        "left": gx > 0.8 * g_mask,
        "right": -gx > 0.8 * g_mask,
        "top": gy > 0.8 * g_mask,
        "bottom": -gy > 0.8 * g_mask,
    }
    moves = np.arange(-reach, reach + 1e-9, STEP)
    out = {}
    for side, sel in facing.items():
        region = ndimage.binary_dilation(sel & edge, iterations=5) & near
        axis = 1 if side in ("left", "right") else 0
        outward = -1.0 if side in ("left", "top") else 1.0
        target = g_img * region
        scores = []
        for s in moves:
            by = [0.0, 0.0]
            by[axis] = outward * s
            moved = ndimage.shift(g_mask, by, order=1) * region
            den = np.sqrt((moved * moved).sum() * (target * target).sum())
            scores.append((moved * target).sum() / den if den else 0.0)
        k = int(np.argmax(scores))
        best = float(moves[k])
        if 0 < k < len(moves) - 1:
            a, b, c = scores[k - 1], scores[k], scores[k + 1]
            curve = a - 2 * b + c
            best += STEP * 0.5 * (a - c) / curve if curve else 0.0
        out[side] = best
    return out


def body_coverage(cap, frame: int, view: int, k: int = 4) -> np.ndarray:
    """(H, W) share of each pixel the posed body covers (rasterised k x finer)."""
    cam = cap.cameras[view]
    fine = rasterize_mesh(cap.posed_body(frame).vertices[0], cap.body.faces, cam.scaled(k)).mask.numpy()
    return fine.reshape(cam.height, k, cam.width, k).mean((1, 3))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("capture")
    ap.add_argument("--frames", type=int, default=16)
    ap.add_argument("--view", type=int, default=0)
    ap.add_argument("--body", action="store_true", help="the posed body's silhouette against the mask")
    args = ap.parse_args(argv)
    cap = open_capture(args.capture, image_scale=1.0, fit_body=args.body)
    frames = np.linspace(0, cap.num_frames - 1, args.frames).round().astype(int)
    print("| frame | " + " | ".join(SIDES) + " | shift x | shift y |")
    print("|---|" + "---|" * (len(SIDES) + 2))
    rows = []
    for t in frames:
        if args.body:
            row = side_offsets(body_coverage(cap, int(t), args.view), cap.mask(args.view, int(t)), reach=8.0)
        else:
            grey = read_image(cap.image_paths[t][args.view]).mean(-1)
            row = side_offsets(grey, read_mask(cap.mask_paths[t][args.view]))
        row["shift_x"] = (row["right"] - row["left"]) / 2
        row["shift_y"] = (row["bottom"] - row["top"]) / 2
        row["grow_x"] = (row["right"] + row["left"]) / 2
        row["grow_y"] = (row["bottom"] + row["top"]) / 2
        rows.append(row)
        cells = [f"{row[k]:+.2f}" for k in (*SIDES, "shift_x", "shift_y")]
        print(f"| {cap.frame_ids[t]} | " + " | ".join(cells) + " |", flush=True)
    keys = (*SIDES, "shift_x", "shift_y", "grow_x", "grow_y")
    mean = {k: float(np.mean([r[k] for r in rows])) for k in keys}
    sem = (
        {k: float(np.std([r[k] for r in rows], ddof=1) / np.sqrt(len(rows))) for k in keys}
        if len(rows) > 1
        else {}
    )
    for k in keys:
        print(f"{k}: {mean[k]:+.2f}" + (f" ± {sem[k]:.2f}" if sem else "") + " px")
    print(
        f"summary: shift_x={mean['shift_x']:+.2f} shift_y={mean['shift_y']:+.2f} "
        f"grow_x={mean['grow_x']:+.2f} grow_y={mean['grow_y']:+.2f} frames={len(rows)}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
