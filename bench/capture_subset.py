"""A few frames of a HumanNeRF-layout capture as a capture of their own: does the field fit
a handful of frames, each drawn many times, better than the whole sequence?

    .venv/bin/python bench/capture_subset.py CAPTURE OUT [--frames 25]

Of ``--frames`` N, ⌊0.8 N⌋ are spread evenly over CAPTURE's training frames and the rest
over its held-out frames, so that OUT's own split (the last 20 % held out) holds out
frames CAPTURE holds out too. OUT gets ``cameras.pkl`` and ``mesh_infos.pkl`` with those
frames' entries as CAPTURE has them, and ``images/`` and ``masks/`` of symbolic links to
CAPTURE's files (nothing is copied, nothing in CAPTURE changes). OUT must not exist.
Then ``texvocab train OUT …`` and ``texvocab eval RUN/checkpoint.pt OUT`` as for any
capture. Prints the chosen frames, the last line ``summary: train=… held_out=…``.

    .venv/bin/python bench/capture_subset.py SUBSET --score CKPT [CKPT ...] [--preset fast]

scores each checkpoint on every training frame of SUBSET (bbox PSNR/SSIM and silhouette
IoU, mean ± standard error, as ``texvocab eval``), whatever capture it trained on: a run on
the subset against a run on the whole capture, on the same frames. The last line is
``summary: CKPT=PSNR …``.
"""

from __future__ import annotations

import argparse
import os
import pickle
import shutil
import sys
from pathlib import Path

import numpy as np

from texvocab.capture import open as open_capture
from texvocab.capture.capture import default_num_train
from texvocab.errors import TexvocabError
from texvocab.io.safe_pickle import read_pickle
from texvocab.io.temp_files import temp_dir


def spread_evenly(ids: list[int], n: int) -> list[int]:
    """``n`` of ``ids`` (sorted), evenly spread from the first; all of them when n >= len."""
    if n >= len(ids):
        return list(ids)
    return [ids[int(i)] for i in np.floor(np.arange(n) * len(ids) / n)]


def choose(train_ids: list[int], novel_ids: list[int], frames: int) -> tuple[list[int], list[int]]:
    """(training, held-out) frame ids of a subset of ``frames`` frames whose own default
    split (:func:`default_num_train`, one camera) keeps the two apart."""
    n_train = default_num_train(frames, 1)
    if n_train > len(train_ids) or frames - n_train > len(novel_ids) or frames - n_train < 1:
        raise TexvocabError(
            f"--frames {frames}: needs {n_train} training and {frames - n_train} held-out "
            f"frames (at least 1); the capture has {len(train_ids)} and {len(novel_ids)}"
        )
    return spread_evenly(train_ids, n_train), spread_evenly(novel_ids, frames - n_train)


def write_subset(capture_dir: Path, out: Path, frames: int) -> tuple[list[int], list[int]]:
    """Write the subset (module docstring) into ``out``, whole or not at all."""
    cap = open_capture(capture_dir)
    if cap.layout != "humannerf":
        raise TexvocabError(f"{capture_dir}: a {cap.layout} capture; expected the HumanNeRF layout")
    if out.exists():
        raise TexvocabError(f"{out}: exists; expected a new folder (nothing is replaced)")
    ids = list(cap.frame_ids)
    train, novel = choose(ids[: cap.num_train], ids[cap.num_train :], frames)
    names = [f"frame_{i:06d}" for i in train + novel]
    tables = {p: read_pickle(capture_dir / p, p) for p in ("cameras.pkl", "mesh_infos.pkl")}
    out.parent.mkdir(parents=True, exist_ok=True)
    stage = temp_dir(out)  # filled, then renamed into place
    try:
        for name, table in tables.items():
            (stage / name).write_bytes(pickle.dumps({n: table[n] for n in names}))
        for folder, paths in (("images", cap.image_paths), ("masks", cap.mask_paths)):
            (stage / folder).mkdir()
            for i in train + novel:
                source = Path(paths[ids.index(i)][0]).resolve()
                os.symlink(source, stage / folder / source.name)
        os.rename(stage, out)
    except BaseException:
        shutil.rmtree(stage)  # the links only, not what they point to
        raise
    return train, novel


def score(subset: Path, checkpoints: list[Path], preset: str | None) -> dict[str, dict]:
    """{checkpoint: texvocab eval's summary (mean and sem per metric, ``images``) and
    ``per_image`` (the bbox PSNR of each frame)} of each checkpoint on every training
    frame of ``subset``."""
    from texvocab.pipeline.avatar import load_avatar
    from texvocab.pipeline.evaluate import CaptureItems, evaluate_sets
    from texvocab.pipeline.settings import march_settings, render_overrides

    sub = open_capture(subset)
    items = CaptureItems(sub, [(t, 0) for t in sub.train_frames], "seen view")
    out = {}
    for ck in checkpoints:
        avatar = load_avatar(ck, progress=False)
        settings = render_overrides(avatar.settings, preset, [])
        march = march_settings(settings)
        table, records, _ = evaluate_sets(
            avatar.model, {"seen": items}, march, scale=settings.render.image_scale, progress=False
        )
        out[str(ck)] = {**table["seen"], "per_image": np.array([r["psnr_bbox"] for r in records])}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("capture", type=Path)
    ap.add_argument("out", type=Path, nargs="?")
    ap.add_argument("--frames", type=int, default=25)
    ap.add_argument("--score", type=Path, nargs="+", metavar="CKPT")
    ap.add_argument("--preset", choices=("fast", "balanced", "quality"), default="fast")
    args = ap.parse_args(argv)
    if (args.out is None) == (args.score is None):
        print(
            "error: give OUT (write a subset) or --score CKPT ... (score checkpoints), one of them",
            file=sys.stderr,
        )
        return 2
    try:
        if args.score:
            rows = score(args.capture, args.score, args.preset)
        else:
            train, novel = write_subset(args.capture, args.out, args.frames)
    except TexvocabError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.score:
        print("| checkpoint | images | psnr_bbox | ssim_bbox | iou | − the first, per image | better |")
        print("|---|---|---|---|---|---|---|")
        first = next(iter(rows.values()))["per_image"]
        for ck, r in rows.items():
            cells = [f"{r[k]:.4f} ± {r[k + '_sem'] or 0:.4f}" for k in ("psnr_bbox", "ssim_bbox", "iou")]
            d = r["per_image"] - first
            paired = f"{d.mean():+.3f} ± {d.std(ddof=1) / np.sqrt(len(d)) if len(d) > 1 else 0:.3f}"
            print(f"| {ck} | {r['images']} | {' | '.join(cells)} | {paired} | {np.mean(d > 0):.0%} |")
        print("summary: " + " ".join(f"{ck}={r['psnr_bbox']:.4f}" for ck, r in rows.items()))
        return 0
    print(f"training frames: {' '.join(map(str, train))}")
    print(f"held-out frames: {' '.join(map(str, novel))}")
    print(f"summary: train={len(train)} held_out={len(novel)} out={args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
