"""Is a frame's appearance the frame d before it, moved? Frame t against frame t − d on
the body's interior, with t − d's pixels as they are, carried by the fitted body (its
texture map laid on frame t's body), and moved by the best local image motion.

    .venv/bin/python bench/frame_motion.py CAPTURE [--frames 10] [--offsets 1 5 10]
        [--block 32] [--reach 24] [--view 0] [--set KEY=VALUE ...] [--out OUT]

Columns (PSNR, dB, mean ± std over frames; every column on the same pixels: inside frame
t's mask and rasterised body, inside frame t − d's mask, on texels frame t − d's map saw):

- ``still``: frame t − d's pixels where they are (no motion at all);
- ``fitted body``: frame t − d's texture map laid on frame t's posed body, what the texture
  path (and any registration by the body fit) carries over (bench/texture_transfer.py's
  ``d=N`` rows, on these pixels);
- ``block-matched``: each ``block``² block of frame t replaced by the block of frame t − d
  that matches it best within ``reach`` pixels (integer shifts): what any locally
  translational motion explains, so a ceiling for what a better fit of the body could
  carry over by moving pixels. Where it is far below frame t's ``own map`` the content
  itself changed; where ``fitted body`` is far below it the fit does not follow the motion.
- ``own map``: frame t's own map laid on its body (what back-projection keeps).

Rows per offset, and per body region (the rasterised face's dominant joint: head, trunk,
arms, legs). Writes OUT/frame_motion.json; the last line printed is ``summary: d=…
still=… fitted=… matched=… own=… frames=…`` for the largest offset, all regions. Nothing
is written into CAPTURE except texvocab's texture cache.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from texture_transfer import training_maps

from texvocab.capture import open as open_capture
from texvocab.geometry.raster import rasterize_mesh
from texvocab.method.texture_transfer import body_view, laid_on
from texvocab.method.unseen_texels import fill_unseen_texels
from texvocab.pipeline.evaluate import spread
from texvocab.pipeline.settings import Settings

COLUMNS = ("still", "fitted body", "block-matched", "own map")
REGIONS = {"head": (12, 15), "trunk": (0, 3, 6, 9, 13, 14), "arms": tuple(range(16, 24))}
REGIONS["legs"] = tuple(j for j in range(24) if not any(j in v for v in REGIONS.values()))
MIN_PIXELS = 64


def block_matched(
    target: np.ndarray, source: np.ndarray, sel: np.ndarray, block: int, reach: int
) -> np.ndarray:
    """(H, W, 3) ``target`` rebuilt from ``source`` (H, W, 3): each ``block``² block of the
    pixels ``sel`` (H, W) replaced by the ``source`` block shifted by the integer (dy, dx),
    |dy|, |dx| <= ``reach``, whose squared error on the block's ``sel`` pixels is least
    (outside ``sel`` the result is ``target``)."""
    ys, xs = np.nonzero(sel)
    if len(ys) == 0:
        return target.copy()
    y0, x0 = ys.min(), xs.min()
    nby, nbx = (ys.max() - y0) // block + 1, (xs.max() - x0) // block + 1
    h, w = nby * block, nbx * block
    # src row reach + i is source row y0 + i (edge pixels repeated outside the image)
    full = np.pad(source, ((reach, reach + h), (reach, reach + w), (0, 0)), mode="edge")
    src = full[y0 : y0 + h + 2 * reach, x0 : x0 + w + 2 * reach]
    tgt = np.zeros((h, w, 3), np.float32)
    m = np.zeros((h, w), np.float32)
    th, tw = min(h, target.shape[0] - y0), min(w, target.shape[1] - x0)
    tgt[:th, :tw] = target[y0 : y0 + th, x0 : x0 + tw]
    m[:th, :tw] = sel[y0 : y0 + th, x0 : x0 + tw]
    best = np.full((nby, nbx), np.inf)
    shift = np.zeros((nby, nbx, 2), int)
    for dy in range(-reach, reach + 1):
        for dx in range(-reach, reach + 1):
            moved = src[reach + dy : reach + dy + h, reach + dx : reach + dx + w]
            err = (((moved - tgt) ** 2).sum(-1) * m).reshape(nby, block, nbx, block).sum((1, 3))
            better = err < best
            best[better] = err[better]
            shift[better] = (dy, dx)
    out = np.zeros_like(tgt)
    for by in range(nby):
        for bx in range(nbx):
            dy, dx = shift[by, bx]
            y, x = by * block, bx * block
            sy, sx = reach + dy + y, reach + dx + x
            out[y : y + block, x : x + block] = src[sy : sy + block, sx : sx + block]
    rebuilt = target.copy()
    keep = sel[y0 : y0 + th, x0 : x0 + tw]
    view = rebuilt[y0 : y0 + th, x0 : x0 + tw]
    view[keep] = out[:th, :tw][keep]
    return rebuilt


def body_regions(capture, frame: int, view: int) -> np.ndarray:
    """(H, W) the region index (REGIONS' order) of the joint that dominates the face of the
    posed body each pixel sees; -1 off the body."""
    body = capture.body
    r = rasterize_mesh(capture.posed_body(frame).vertices[0].double(), body.faces, capture.cameras[view])
    face = r.face.numpy()
    joint = body.weights.numpy()[body.faces.numpy()[:, 0]].argmax(1)
    lookup = np.full(24, -1)
    for k, joints in enumerate(REGIONS.values()):
        lookup[list(joints)] = k
    out = np.full(face.shape, -1)
    out[face >= 0] = lookup[joint[face[face >= 0]]]
    return out


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    return float(-10.0 * np.log10(max(float(np.mean((a - b) ** 2)), 1e-12)))


def measure(
    capture, maps: np.ndarray, coverage: np.ndarray, frames, offsets, block: int, reach: int, view: int
) -> dict:
    """{offset: {region: {column: [PSNR per frame]}}} (region "all" too) for ``frames``;
    ``maps`` (T, S, S, 3) the training frames' maps (unseen texels filled), ``coverage``
    (T, S, S)."""
    size = maps.shape[1]
    names = ("all", *REGIONS)
    table: dict = {d: {name: {c: [] for c in COLUMNS} for name in names} for d in offsets}
    for t in frames:
        bv = body_view(capture, t, view, size)
        regions = body_regions(capture, t, view)
        own = laid_on(bv, maps[t])
        for d in offsets:
            s = t - d
            seen = laid_on(bv, (coverage[s] > 0)[..., None].astype(np.float32))[..., 0] > 0.99
            mask_s = capture.mask(view, s) > 0.5
            sel = bv.interior & mask_s & seen
            source = capture.image(view, s)
            images = {
                "still": source,
                "fitted body": laid_on(bv, maps[s]),
                "block-matched": block_matched(bv.image, source, sel, block, reach),
                "own map": own,
            }
            for name in ("all", *REGIONS):
                px = sel if name == "all" else sel & (regions == list(REGIONS).index(name))
                if px.sum() < MIN_PIXELS:
                    continue
                for c, img in images.items():
                    table[d][name][c].append(_psnr(img[px], bv.image[px]))
    return table


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("capture", type=Path)
    ap.add_argument("--frames", type=int, default=10, help="training frames scored, evenly spread")
    ap.add_argument("--offsets", type=int, nargs="+", default=[1, 5, 10])
    ap.add_argument("--block", type=int, default=32, help="block side, pixels at the capture's scale")
    ap.add_argument("--reach", type=int, default=24, help="largest shift tried, pixels")
    ap.add_argument("--view", type=int, default=0)
    ap.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--out", type=Path, default=Path("out/frame_motion"))
    args = ap.parse_args(argv)
    if min(args.frames, args.block, *args.offsets) < 1 or args.reach < 0:
        sys.exit("error: --frames, --block and --offsets must be positive and --reach not negative")
    s = Settings().with_overrides(args.sets)
    cap = open_capture(args.capture)
    if cap.body.vt is None:
        sys.exit(f"error: {args.capture}: its body has no UV layout")
    if not 0 <= args.view < len(cap.cameras):
        sys.exit(f"error: --view {args.view}: the capture has cameras 0 to {len(cap.cameras) - 1}")
    first = max(args.offsets)
    if first >= cap.num_train:
        sys.exit(f"error: --offsets {first}: the capture has only {cap.num_train} training frames")
    raw, coverage = training_maps(cap, s)
    maps = fill_unseen_texels(raw, coverage, s.data.unseen_texels).permute(0, 2, 3, 1).numpy()
    frames = spread(list(range(first, cap.num_train)), args.frames)
    table = measure(cap, maps, coverage.numpy(), frames, args.offsets, args.block, args.reach, args.view)
    print(f"# frame t against frame t - d: {args.capture}, camera {args.view}, {len(frames)} frames")
    print(f"block {args.block}, reach {args.reach} px at {cap.cameras[args.view].width} px wide\n")
    print("| d | region | frames | " + " | ".join(COLUMNS) + " |\n" + "|---" * (len(COLUMNS) + 3) + "|")
    for d, regions in table.items():
        for name, cols in regions.items():
            n = len(cols["still"])
            if n == 0:
                continue
            cells = [
                f"{np.mean(v):.2f} ± {np.std(v, ddof=1) if len(v) > 1 else 0:.2f}" if v else "n/a"
                for v in cols.values()
            ]
            print(f"| {d} | {name} | {n} | " + " | ".join(cells) + " |")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "frame_motion.json").write_text(json.dumps({"frames": frames, "table": table}))
    top = table[max(args.offsets)]["all"]
    print(
        f"summary: d={max(args.offsets)} still={np.mean(top['still']):.2f} "
        f"fitted={np.mean(top['fitted body']):.2f} matched={np.mean(top['block-matched']):.2f} "
        f"own={np.mean(top['own map']):.2f} frames={len(frames)}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
