"""Does the averaged weights' score hold still where the raw weights' swings? One run with
``train.weight_average`` on, trained to ``--steps``, then continued ``--every`` steps at a
time; at each stop both its raw weights and their average are scored on the same novel
images (their difference paired per image). Training steps the raw weights alone, so the
raw column is the run without the average.

    .venv/bin/python bench/weight_average.py CAPTURE [--out OUT] [--steps 6000]
        [--every 50] [--stops 7] [--decay 0.995] [--set KEY=VALUE ...] [--per-set N]
        [--preset fast]

A finished stop is reused, so a second call only does what is missing. Prints one row per
stop (step, raw and averaged bbox PSNR ± standard error and silhouette IoU, the paired
difference) and as its last line ``summary: stops=… first_step=… last_step=…
raw_mean=… raw_swing=… average_mean=… average_swing=… delta_db=… images=…`` (swing: max −
min of a column's mean PSNR over the stops; delta: average − raw, mean over every stop's
paired images). Writes OUT/weight_average.json.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from train_budget import TEXVOCAB, _run, score

from texvocab.io.checkpoint import load_checkpoint, save_checkpoint
from texvocab.io.images import atomic_write_bytes
from texvocab.pipeline.weight_average import TRAINED_KEY, trained_state


def raw_checkpoint(ckpt: Path, dest: Path) -> None:
    """``ckpt`` with its raw trained weights in ``model`` (the run without the average)."""
    ck = load_checkpoint(ckpt)
    if TRAINED_KEY not in ck:
        sys.exit(f"error: {ckpt}: holds no weight average (train.weight_average=0)")
    ck["model"] = trained_state(ck)
    del ck[TRAINED_KEY]
    ck["settings"]["train"]["weight_average"] = 0.0
    save_checkpoint(dest, ck)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("capture", type=Path)
    ap.add_argument("--out", type=Path, default=Path("out/weight_average"))
    ap.add_argument("--steps", type=int, default=6000)
    ap.add_argument("--every", type=int, default=50)
    ap.add_argument("--stops", type=int, default=7)
    ap.add_argument("--decay", type=float, default=0.995)
    ap.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--per-set", type=int, default=None)
    ap.add_argument("--preset", choices=("fast", "balanced", "quality"), default=None)
    args = ap.parse_args(argv)
    if not args.capture.is_dir():
        sys.exit(f"error: {args.capture}: not a capture folder")
    if args.steps < 1 or args.every < 1 or args.stops < 1:
        sys.exit("error: --steps, --every and --stops: expected counts of 1 or more")
    if not 0 < args.decay < 1:
        sys.exit(f"error: --decay {args.decay}: expected 0 < decay < 1")
    args.out.mkdir(parents=True, exist_ok=True)
    log, run = args.out / "commands.log", args.out / "run"
    sets = [f"train.weight_average={args.decay}", *args.sets]
    rows = []
    for i in range(args.stops):
        step = args.steps + i * args.every
        stop = args.out / f"step{step}"
        averaged = stop / "averaged.pt"
        if not averaged.is_file():
            resume = ["--resume"] if (run / "checkpoint.pt").is_file() else []
            _run(
                [*TEXVOCAB, "train", str(args.capture), "--out", str(run), "--iterations", str(step), *resume]
                + [a for s in sets for a in ("--set", s)],
                log,
            )
            stop.mkdir(exist_ok=True)
            raw_checkpoint(run / "checkpoint.pt", stop / "raw.pt")
            save_checkpoint(averaged, load_checkpoint(run / "checkpoint.pt"))
        raw = score(stop / "raw.pt", args.capture, stop / "eval_raw", args, log)
        avg = score(averaged, args.capture, stop / "eval_averaged", args, log)
        keys = sorted(set(raw["per_image"]) & set(avg["per_image"]))
        d = np.array([avg["per_image"][k] - raw["per_image"][k] for k in keys])
        rows.append({"step": step, "raw": raw["row"], "averaged": avg["row"], "paired": d.tolist()})
    print(
        "| step | images | raw PSNR bbox | raw IoU | averaged PSNR bbox | averaged IoU "
        "| paired, averaged − raw |"
    )
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        d = np.array(r["paired"])
        sem = d.std(ddof=1) / np.sqrt(len(d)) if len(d) > 1 else 0.0
        a, b = r["raw"], r["averaged"]
        print(
            f"| {r['step']} | {len(d)} | {a['psnr_bbox']:.2f} ± {a['psnr_bbox_sem']:.2f} | "
            f"{a.get('iou', float('nan')):.3f} | {b['psnr_bbox']:.2f} ± {b['psnr_bbox_sem']:.2f} | "
            f"{b.get('iou', float('nan')):.3f} | {d.mean():+.2f} ± {sem:.2f} dB |"
        )
    raw_means = np.array([r["raw"]["psnr_bbox"] for r in rows])
    avg_means = np.array([r["averaged"]["psnr_bbox"] for r in rows])
    every = np.concatenate([r["paired"] for r in rows])
    blob = {"capture": str(args.capture), "decay": args.decay, "sets": args.sets, "stops": rows}
    text = json.dumps(blob, indent=1)
    atomic_write_bytes(args.out / "weight_average.json", lambda t: Path(t).write_text(text))
    print(
        f"summary: stops={len(rows)} first_step={rows[0]['step']} last_step={rows[-1]['step']} "
        f"raw_mean={raw_means.mean():.3f} raw_swing={np.ptp(raw_means):.3f} "
        f"average_mean={avg_means.mean():.3f} average_swing={np.ptp(avg_means):.3f} "
        f"delta_db={every.mean():.3f} images={len(rows[0]['paired'])}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
