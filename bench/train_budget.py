"""Quality per minute of training: a reference run with a longer time budget and a run with
a shorter one (and settings of its own), one after the other on the same machine, both
evaluated on the same novel images, paired per image.

    .venv/bin/python bench/train_budget.py CAPTURE [--out OUT] [--minutes 10]
        [--reference-minutes 20] [--set KEY=VALUE ...] [--reference-set KEY=VALUE ...]
        [--seed 0] [--per-set N] [--preset fast]

``--set`` applies to the short run only, ``--reference-set`` to the reference only (both
on top of the defaults). The runs train one at a time (OUT/reference, OUT/short), each with
the machine's threads; a finished run is reused, so a second call only evaluates what is
missing (a run stopped before its budget was spent is an error: remove it). Each is then
scored by ``texvocab eval`` on its novel set (held-out views and frames; ``--per-set``
images per set, all by default).

Prints one row per run (minutes, steps, bbox PSNR ± standard error, SSIM, silhouette IoU)
and the paired difference per image, and as its last line ``summary: short_minutes=…
short_steps=… short_psnr_bbox=… reference_minutes=… reference_steps=…
reference_psnr_bbox=… delta_db=… delta_sem=… better=… images=…`` (delta: short −
reference, mean over the paired images). Writes OUT/train_budget.json.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from texvocab.io.checkpoint import load_checkpoint
from texvocab.io.images import atomic_write_bytes

TEXVOCAB = [sys.executable, "-m", "texvocab.cli.main"]
SET = "novel_poses"


def _run(cmd: list[str], log: Path) -> None:
    with open(log, "a") as fh:
        fh.write(f"$ {' '.join(cmd)}\n")
        fh.flush()
        rc = subprocess.call(cmd, stdout=fh, stderr=subprocess.STDOUT)
    if rc != 0:
        sys.exit(f"error: texvocab {cmd[3]} failed (exit {rc}); see {log}")


def train_and_score(capture: Path, run: Path, minutes: float, sets: list[str], args, log: Path) -> dict:
    """Train ``run`` for ``minutes`` (unless its checkpoint exists) and evaluate it; its
    steps, the novel set's row and the per-image bbox PSNR by (frame, view) or index."""
    ckpt, done = run / "checkpoint.pt", run / "budget_spent"
    if ckpt.is_file() and not done.is_file():
        sys.exit(f"error: {run}: a run that did not finish its budget; remove it to train it again")
    if not done.is_file():
        items = [f"train.seed={args.seed}", f"train.max_minutes={minutes}", *sets]
        _run(
            [*TEXVOCAB, "train", str(capture), "--out", str(run), "--iterations", "10000000"]
            + [a for s in items for a in ("--set", s)],
            log,
        )
        done.write_text(f"{minutes}\n")
    return {"minutes": minutes, "steps": int(load_checkpoint(ckpt)["step"]), "sets": sets} | score(
        ckpt, capture, run / "eval", args, log
    )


def score(ckpt: Path, capture: Path, report: Path, args, log: Path) -> dict:
    """``texvocab eval`` of ``ckpt`` into ``report`` (reused when there; ``--per-set`` and
    ``--preset`` from ``args``): the novel set's row and its per-image bbox PSNR by
    (frame, view) or index."""
    if not (report / "metrics.json").is_file():
        per_set = [] if args.per_set is None else ["--per-set", str(args.per_set)]
        preset = [] if args.preset is None else ["--preset", args.preset]
        _run([*TEXVOCAB, "eval", str(ckpt), str(capture), "--out", str(report), *per_set, *preset], log)
    metrics = json.loads((report / "metrics.json").read_text())
    images = [r for r in metrics["images"] if r["set"] == SET]
    per_image = {(r.get("frame", r["index"]), r.get("view", 0)): r["psnr_bbox"] for r in images}
    return {"row": metrics["table"][SET], "per_image": per_image}


def paired(short: dict, reference: dict) -> dict:
    """Mean, standard error and share better of short − reference over the shared images."""
    keys = sorted(set(short["per_image"]) & set(reference["per_image"]))
    d = np.array([short["per_image"][k] - reference["per_image"][k] for k in keys])
    sem = float(d.std(ddof=1) / np.sqrt(len(d))) if len(d) > 1 else 0.0
    return {"images": len(d), "delta_db": float(d.mean()), "delta_sem": sem, "better": float((d > 0).mean())}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("capture", type=Path)
    ap.add_argument("--out", type=Path, default=Path("out/train_budget"))
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--reference-minutes", type=float, default=20.0)
    ap.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument(
        "--reference-set", dest="reference_sets", action="append", default=[], metavar="KEY=VALUE"
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--per-set", type=int, default=None)
    ap.add_argument("--preset", choices=("fast", "balanced", "quality"), default=None)
    args = ap.parse_args(argv)
    if not args.capture.is_dir():
        sys.exit(f"error: {args.capture}: not a capture folder")
    if args.minutes <= 0 or args.reference_minutes <= 0:
        sys.exit("error: --minutes and --reference-minutes: expected times above 0")
    args.out.mkdir(parents=True, exist_ok=True)
    log = args.out / "commands.log"
    ref = train_and_score(
        args.capture, args.out / "reference", args.reference_minutes, args.reference_sets, args, log
    )
    short = train_and_score(args.capture, args.out / "short", args.minutes, args.sets, args, log)
    diff = paired(short, ref)
    print("| run | minutes | steps | settings | images | PSNR bbox | SSIM bbox | silhouette IoU |")
    print("|---|---|---|---|---|---|---|---|")
    for name, r in (("reference", ref), ("short", short)):
        row = r["row"]
        print(
            f"| {name} | {r['minutes']:g} | {r['steps']} | {' '.join(r['sets']) or 'defaults'} | "
            f"{row['images']} | {row['psnr_bbox']:.2f} ± {row['psnr_bbox_sem']:.2f} | "
            f"{row['ssim_bbox']:.4f} | {row.get('iou', float('nan')):.3f} |"
        )
    print(
        f"paired, short − reference: {diff['delta_db']:+.2f} ± {diff['delta_sem']:.2f} dB over "
        f"{diff['images']} images, better on {100 * diff['better']:.0f} %"
    )
    blob = {
        "capture": str(args.capture),
        "seed": args.seed,
        "reference": {k: v for k, v in ref.items() if k != "per_image"},
        "short": {k: v for k, v in short.items() if k != "per_image"},
        "paired": diff,
    }
    text = json.dumps(blob, indent=1)
    atomic_write_bytes(args.out / "train_budget.json", lambda t: Path(t).write_text(text))
    print(
        f"summary: short_minutes={args.minutes:g} short_steps={short['steps']} "
        f"short_psnr_bbox={short['row']['psnr_bbox']:.3f} reference_minutes={args.reference_minutes:g} "
        f"reference_steps={ref['steps']} reference_psnr_bbox={ref['row']['psnr_bbox']:.3f} "
        f"delta_db={diff['delta_db']:.3f} delta_sem={diff['delta_sem']:.3f} "
        f"better={diff['better']:.2f} images={diff['images']}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
