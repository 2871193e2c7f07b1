"""Does a body texel look the same in other frames? Texture maps laid on a frame's posed
body against the frame's image, before any training (``texvocab.method.texture_transfer``).

    .venv/bin/python bench/texture_transfer.py CAPTURE [--frames 24] [--offsets 1 2 5 10 20 40]
        [--set KEY=VALUE ...] [--out OUT]

Rows (PSNR on the interior: pixels inside both the mask and the rasterised body, mean ±
std over frames, as is and after a 3 px blur of both images):

- ``own``: the frame's own map (what back-projection keeps; an upper bound);
- ``d=N``: the map of the frame N before it, on texels both maps saw;
- ``vocabulary blend``: the vocabulary's texture for a held-out frame's pose (Eq. 5 on
  the maps, the default ``vocab`` settings or ``--set``), all texels;
- ``mean texture``: the training frames' coverage-weighted mean, the same held-out frames.

The texture path can give the field no more than the blend row; where the blend is no
better than the mean texture, the vocabulary's keys carry no appearance the pose could
select. Writes OUT/texture_transfer.json and .md; the last line printed is
``summary: own=… d1=… dmax=… blend=… mean=… frames=…``. Nothing is written into CAPTURE
except texvocab's texture cache.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import torch

from texvocab.capture import open as open_capture
from texvocab.method.texmap import load_texture_map, prepare_texture_maps
from texvocab.method.texture_transfer import transfer_scores
from texvocab.method.unseen_texels import fill_unseen_texels, mean_texture
from texvocab.method.vocab_texture import VocabTexture
from texvocab.pipeline.evaluate import spread
from texvocab.pipeline.model import build_vocabulary, texmap_settings
from texvocab.pipeline.settings import Settings


def _commit() -> str:
    try:
        cmd = ["git", "rev-parse", "--short", "HEAD"]
        return subprocess.run(cmd, capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def _fmt(v: float | None, s: float | None) -> str:
    if v is None:
        return "n/a"
    return f"{v:.2f}" + ("" if s is None else f" ± {s:.2f}")


def format_table(table: dict[str, dict]) -> str:
    lines = [
        "| texture | frames | PSNR interior (dB) | PSNR, 3 px blur (dB) |",
        "|---|---|---|---|",
    ]
    for name, r in table.items():
        lines.append(
            f"| {name} | {r['frames']} | {_fmt(r['psnr'], r['psnr_std'])} | "
            f"{_fmt(r['psnr_blurred'], r['psnr_blurred_std'])} |"
        )
    return "\n".join(lines)


def training_maps(cap, s: Settings) -> tuple[torch.Tensor, torch.Tensor]:
    """The training frames' texture maps (T, 3, S, S) as back-projected (unseen texels 0)
    and their coverage (T, S, S), built into the capture's texture cache if need be."""
    paths = prepare_texture_maps(cap, texmap_settings(cap, s), progress=True)
    maps = [load_texture_map(p) for p in paths]
    raw = torch.stack([torch.from_numpy(t).permute(2, 0, 1) for t, _ in maps])
    return raw, torch.stack([torch.from_numpy(c) for _, c in maps])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("capture", type=Path)
    ap.add_argument("--frames", type=int, default=24, help="frames per set, evenly spread")
    ap.add_argument("--offsets", type=int, nargs="+", default=[1, 2, 5, 10, 20, 40])
    ap.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--out", type=Path, default=Path("out/texture_transfer"))
    args = ap.parse_args(argv)
    if args.frames < 1 or any(d < 1 for d in args.offsets):
        sys.exit("error: --frames and --offsets must be positive")
    s = Settings().with_overrides(args.sets)
    cap = open_capture(args.capture)
    if cap.body.vt is None:
        sys.exit(f"error: {args.capture}: its body has no UV layout")
    raw, coverage = training_maps(cap, s)
    filled = fill_unseen_texels(raw, coverage, s.data.unseen_texels).permute(0, 2, 3, 1).numpy()
    mean = mean_texture(raw, coverage).permute(1, 2, 0).numpy()
    vocab = build_vocabulary(cap, s)
    blend = VocabTexture(cap.body, vocab, filled).blend
    first = min(max(args.offsets), cap.num_train - 1)  # frames with every offset before them
    train = spread(list(range(first, cap.num_train)), args.frames)
    novel = spread(list(range(cap.num_train, cap.num_frames)), args.frames)
    if not novel:  # every frame trains: score the blend on training frames that are no key
        keys = {int(f) for kf in vocab.key_frames for f in np.asarray(kf).ravel()}
        novel = spread([t for t in range(cap.num_train) if t not in keys], args.frames)
    table = transfer_scores(cap, filled, coverage.numpy(), train, novel, tuple(args.offsets), blend, mean)
    stamp = (
        f"commit `{_commit()}` · `bench/texture_transfer.py {args.capture.name} --frames {args.frames}"
        + "".join(f" --set {x}" for x in args.sets)
        + "`"
    )
    md = "\n".join(
        [
            f"# Texture transfer: {args.capture}",
            "",
            f"{cap.layout} layout, {cap.num_train} training frames, {cap.num_frames - cap.num_train} "
            f"held out, texture {s.data.texture_size}², camera 0; {stamp}",
            "",
            format_table(table),
            "",
        ]
    )
    args.out.mkdir(parents=True, exist_ok=True)
    record = {"table": table, "train_frames": train, "novel_frames": novel, "sets": args.sets}
    (args.out / "texture_transfer.json").write_text(json.dumps(record))
    (args.out / "texture_transfer.md").write_text(md)
    print(md)
    dmax = f"d={max(args.offsets)}"
    print(
        f"summary: own={table['own']['psnr']} d1={table.get('d=1', {}).get('psnr')} "
        f"dmax={table[dmax]['psnr']} blend={table['vocabulary blend']['psnr']} "
        f"mean={table['mean texture']['psnr']} frames={len(train)}+{len(novel)}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
