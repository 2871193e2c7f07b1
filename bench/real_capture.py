"""A real capture end to end: the body fit, texture maps, a time-budgeted training run and
the evaluation of its held-out frames, as one table.

    .venv/bin/python bench/real_capture.py CAPTURE [--out OUT] [--minutes 20] [--seed 0]
        [--set KEY=VALUE ...] [--per-set N] [--fit-every 5] [--coverage-every 20]

Steps (each printed as it finishes; finished steps are reused on a second run):

1. **The body against the masks**: the posed body's silhouette IoU against every
   ``--fit-every``-th frame's mask, with the embedded default body as it is and fitted to the
   capture's rest joints (``texvocab.capture.subject``), and the share of mask pixels whose
   ray passes within 2-10 cm of the fitted body (every ``--coverage-every``-th frame): how
   wide the field's shell must be for this capture.
2. ``texvocab prepare`` (texture maps of the training frames, Eq. 2).
3. ``texvocab train`` for ``--minutes`` on this machine's cores, ``--set`` on top of the
   defaults (OUT/run/).
4. ``texvocab eval`` of every held-out frame (a one-camera capture: its last frames, seen from
   its camera) and as many training frames (seen views): bbox and full-frame PSNR/SSIM,
   LPIPS where its weights exist, KID, the rendered silhouette's IoU; mean ± standard error
   with the image counts (OUT/run/eval/metrics.md).

Writes OUT/real_capture.md and OUT/real_capture.json; the last line printed is
``summary: novel_psnr_bbox=… novel_iou=… fit_iou_before=… fit_iou_after=… steps=…``.
Nothing is written into CAPTURE except texvocab's own cache (texvocab_cache/).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from texvocab.capture import open as open_capture
from texvocab.capture.silhouette import shell_coverage, silhouette_fit
from texvocab.io.checkpoint import load_checkpoint
from texvocab.method.pose_refinement import refined_poses

DELTAS = (0.02, 0.04, 0.06, 0.08, 0.10)
TEXVOCAB = [sys.executable, "-m", "texvocab.cli.main"]


def _iou_row(res, frames: list[int]) -> dict:
    iou = np.asarray(res.iou)
    return {
        "frames": len(frames),
        "iou_mean": float(iou.mean()),
        "iou_std": float(iou.std(ddof=1)) if len(iou) > 1 else 0.0,
        "iou_min": float(iou.min()),
        "precision": float(np.mean(res.precision)),
        "recall": float(np.mean(res.recall)),
    }


def body_against_masks(capture: Path, every: int, coverage_every: int) -> dict:
    """Silhouette IoU (mean, std, min over frames) of the default and the fitted body, and
    the fitted body's shell coverage per δ."""
    out = {}
    for name, fit in (("default", False), ("fitted", True)):
        cap = open_capture(capture, fit_body=fit)
        frames = list(range(0, cap.num_frames, every))
        res = silhouette_fit(
            cap.body,
            cap.poses[frames],
            cap.trans[frames],
            cap.cameras[0],
            (cap.mask(0, t) for t in frames),
            cap.shape(),
        )
        out[name] = _iou_row(res, frames)
        if fit:
            cf = list(range(0, cap.num_frames, coverage_every))
            cov = shell_coverage(
                cap.body,
                cap.poses[cf],
                cap.trans[cf],
                cap.cameras[0],
                (cap.mask(0, t) for t in cf),
                DELTAS,
                betas=cap.shape(),
            )
            out["coverage"] = {
                "frames": len(cf),
                **{f"{d:g}": float(c) for d, c in zip(DELTAS, cov.mean(0), strict=True)},
                "worst_4cm": float(cov[:, 1].min()),
            }
    return out


def refined_against_masks(capture: Path, ck: dict, every: int) -> dict | None:
    """Silhouette IoU of the fitted body on every ``every``-th training frame, with the
    recorded poses and with the run's refined ones (None when it refined none)."""
    state = ck.get("pose_refinement")
    if state is None:
        return None
    cap = open_capture(capture)
    frames = list(range(0, len(state["trans"]), every))
    poses, trans = refined_poses(state, cap.poses, cap.trans)
    out = {}
    for name, (p, t) in (
        ("recorded", (cap.poses[frames], cap.trans[frames])),
        ("refined", (poses[frames], trans[frames])),
    ):
        res = silhouette_fit(cap.body, p, t, cap.cameras[0], (cap.mask(0, f) for f in frames), cap.shape())
        out[name] = _iou_row(res, frames)
    return out


def run(cmd: list[str], log: Path) -> None:
    """Run a texvocab command, its output appended to ``log``; exits on failure."""
    with open(log, "a") as fh:
        fh.write(f"$ {' '.join(cmd)}\n")
        fh.flush()
        rc = subprocess.call(cmd, stdout=fh, stderr=subprocess.STDOUT)
    if rc != 0:
        sys.exit(f"error: {' '.join(cmd[2:4])} failed (exit {rc}); see {log}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("capture", type=Path)
    ap.add_argument("--out", type=Path, default=Path("out/real_capture"))
    ap.add_argument("--minutes", type=float, default=20.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--per-set", type=int, default=None)
    ap.add_argument("--fit-every", type=int, default=5)
    ap.add_argument("--coverage-every", type=int, default=20)
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    log = args.out / "commands.log"
    result: dict = {
        "capture": str(args.capture),
        "minutes": args.minutes,
        "seed": args.seed,
        "sets": args.sets,
    }
    cap = open_capture(args.capture)
    result["capture_info"] = {
        "layout": cap.layout,
        "views": cap.num_views,
        "frames": cap.num_frames,
        "train_frames": cap.num_train,
        "novel_frames": cap.num_frames - cap.num_train,
        "image": f"{cap.cameras[0].width}x{cap.cameras[0].height}",
        "image_scale": cap.image_scale,
        "body_fit": cap.meta.get("body_fit"),
    }
    print("capture:", result["capture_info"], flush=True)

    t0 = time.perf_counter()
    result["body"] = body_against_masks(args.capture, args.fit_every, args.coverage_every)
    print(f"body against masks ({time.perf_counter() - t0:.0f} s):", result["body"], flush=True)

    sets = [
        a
        for s in [f"train.seed={args.seed}", f"train.max_minutes={args.minutes}", *args.sets]
        for a in ("--set", s)
    ]
    run_dir = args.out / "run"
    t0 = time.perf_counter()
    size = [
        a.split("=", 1)[1] for a in args.sets if a.split("=", 1)[0] in ("data.texture_size", "texture_size")
    ]
    run([*TEXVOCAB, "prepare", str(args.capture), *(["--texture-size", size[-1]] if size else [])], log)
    result["prepare_seconds"] = time.perf_counter() - t0
    ckpt = run_dir / "checkpoint.pt"
    if not ckpt.is_file():
        t0 = time.perf_counter()
        run(
            [*TEXVOCAB, "train", str(args.capture), "--out", str(run_dir), "--iterations", "1000000", *sets],
            log,
        )
        result["train_seconds"] = time.perf_counter() - t0
    ck = load_checkpoint(ckpt)
    result["steps"] = int(ck["step"])
    result["refined"] = refined_against_masks(args.capture, ck, args.fit_every)
    per_set = [] if args.per_set is None else ["--per-set", str(args.per_set)]
    t0 = time.perf_counter()
    run([*TEXVOCAB, "eval", str(ckpt), str(args.capture), *per_set], log)
    result["eval_seconds"] = time.perf_counter() - t0
    metrics = json.loads((run_dir / "eval" / "metrics.json").read_text())
    result["table"] = metrics["table"]
    (args.out / "real_capture.json").write_text(json.dumps(result, indent=1))
    md = format_report(result)
    (args.out / "real_capture.md").write_text(md)
    print(md)
    novel, b = result["table"].get("novel_poses", {}), result["body"]
    print(
        f"summary: novel_psnr_bbox={novel.get('psnr_bbox')} novel_iou={novel.get('iou')} "
        f"fit_iou_before={b['default']['iou_mean']:.3f} fit_iou_after="
        f"{b['fitted']['iou_mean']:.3f} steps={result['steps']}"
    )
    return 0


def _pm(row: dict, key: str, digits: int) -> str:
    v, s = row.get(key), row.get(f"{key}_sem")
    if v is None:
        return "n/a"
    return f"{v:.{digits}f}" + ("" if s is None else f" ± {s:.{digits}f}")


def format_report(r: dict) -> str:
    c, b = r["capture_info"], r["body"]
    lines = [
        f"# Real capture: {r['capture']}",
        "",
        f"{c['layout']} layout, {c['views']} view(s), {c['frames']} frames "
        f"({c['train_frames']} train, {c['novel_frames']} held out), images at "
        f"{c['image']} (scale {c['image_scale']:g}), body fit {c['body_fit']}. "
        f"Trained {r['minutes']:g} min (seed {r['seed']}, {r['steps']} steps), settings "
        f"{' '.join(r['sets']) or 'defaults'}.",
        "",
        "| body | frames | IoU mean ± std (min) | precision | recall |",
        "|---" * 5 + "|",
    ]
    for name in ("default", "fitted"):
        x = b[name]
        lines.append(
            f"| {name} | {x['frames']} | {x['iou_mean']:.3f} ± {x['iou_std']:.3f} "
            f"({x['iou_min']:.3f}) | {x['precision']:.3f} | {x['recall']:.3f} |"
        )
    for name, x in (r.get("refined") or {}).items():
        lines.append(
            f"| training frames, {name} poses | {x['frames']} | {x['iou_mean']:.3f} ± "
            f"{x['iou_std']:.3f} ({x['iou_min']:.3f}) | {x['precision']:.3f} | {x['recall']:.3f} |"
        )
    cov = b["coverage"]
    lines += [
        "",
        f"Share of mask pixels whose ray passes within δ of the fitted body "
        f"({cov['frames']} frames): "
        + ", ".join(f"{float(d) * 100:g} cm {cov[d]:.3f}" for d in (f"{x:g}" for x in DELTAS))
        + f"; worst frame at 4 cm {cov['worst_4cm']:.3f}.",
        "",
        "| set | images | psnr_bbox | ssim_bbox | psnr_full | ssim_full | lpips | kid | iou |",
        "|---" * 9 + "|",
    ]
    for name, row in r["table"].items():
        shown = f"{name} ({row['views']})" if row.get("views") else name
        kid = "n/a" if row.get("kid") is None else f"{row['kid']:.4f}"
        lines.append(
            f"| {shown} | {row.get('images')} | {_pm(row, 'psnr_bbox', 2)} | "
            f"{_pm(row, 'ssim_bbox', 4)} | {_pm(row, 'psnr_full', 2)} | "
            f"{_pm(row, 'ssim_full', 4)} | {_pm(row, 'lpips', 4)} | {kid} | "
            f"{_pm(row, 'iou', 3)} |"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
