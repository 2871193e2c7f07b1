"""Vocabulary strategy ablation (paper Sec. 4.3, Table 4) on novel poses, in one run:
``part`` / ``joint`` / ``global`` vocabularies and the ``none`` baseline (no texture
feature: the pose is the field's only condition), the same capture, settings and step
budget, each trained once per seed and evaluated on the same held-out views and novel
frames.

    .venv/bin/python bench/strategies.py [CAPTURE] [--motion compositional] [--seeds 0 1 2]
        [--iterations 300] [--per-set 10] [--preset fast] [--set weighting=inverse]

Without CAPTURE a synthetic capture is made under OUT/capture_<motion>: by default the
compositional one (``texvocab synth --motion compositional``), whose novel frames put part
poses seen in training into whole-body combinations never seen, the case the paper's
body-part vocabulary is built for. Training is budgeted in steps, not minutes; runs resume
from OUT/<strategy>/seed<S>/checkpoint.pt.

Reports, for the novel-pose set (``--per-set`` frames x every evaluation view): per
strategy the mean over seeds of each run's mean PSNR/SSIM (mask bounding box) and LPIPS
(when its weights exist) with the spread over seeds (max - min); and the *paired*
per-seed differences part - joint, part - global and part - none (same seed, same images),
with their range over seeds: a difference whose range straddles 0 is not resolved.
Writes strategies.md / .json and side_by_side.png (truth | one column per strategy, seed
0, the same novel frames) to OUT.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from texvocab.io.images import atomic_write_bytes, contact_sheet, save_png

METRICS = ("psnr_bbox", "ssim_bbox", "lpips")
SET = "novel_poses"


def make_capture(out: Path, motion: str) -> Path:
    """The synthetic capture of ``motion`` under OUT (reused when present)."""
    from texvocab.body import load_body
    from texvocab.capture.synth import synthesize

    root = out / f"capture_{motion}"
    if not root.exists():
        if motion == "compositional":
            from texvocab.capture.compositional import compositional_motion as make
        else:
            from texvocab.capture.motion import default_motion as make
        poses, trans, num_train = make(0)
        synthesize(root, poses, trans, num_train, load_body(None))
    return root


def train_and_evaluate(root: Path, strategy: str, seed: int, args) -> dict:
    from texvocab.capture import open as open_capture
    from texvocab.pipeline.evaluate import build_sets, evaluate_sets, write_report
    from texvocab.pipeline.settings import Settings, march_settings, preset_overrides
    from texvocab.pipeline.train import Trainer

    run_dir = Path(args.out) / strategy / f"seed{seed}"
    cap = open_capture(root)
    pre = preset_overrides(args.preset, render_only=True) if args.preset else []
    settings = Settings(strategy=strategy, iterations=args.iterations).with_overrides(
        pre + args.overrides + [f"seed={seed}"])
    trainer = Trainer(cap, settings, run_dir, progress=False)
    trainer.resume()
    t0 = time.perf_counter()
    trainer.run()
    train_s = time.perf_counter() - t0
    trainer.model.eval()
    sets = {SET: build_sets(cap, settings, args.per_set, generated=())[SET]}
    t0 = time.perf_counter()
    table, records, grids = evaluate_sets(trainer.model, sets, march_settings(settings),
                                          grid_rows=args.grid_rows, progress=False)
    write_report(run_dir / "eval", table, records, grids,
                 {"checkpoint": str(trainer.checkpoint_path), "step": trainer.step,
                  "capture": str(root), "settings": settings.to_dict()})
    print(f"{strategy} seed {seed}: {trainer.step} steps ({train_s / 60:.1f} min), "
          f"{len(sets[SET])} novel images ({(time.perf_counter() - t0) / 60:.1f} min), "
          f"PSNR {table[SET]['psnr_bbox']:.2f} dB", flush=True)
    per_image = {m: [r.get(m) for r in records if r["set"] == SET] for m in METRICS}
    return {"strategy": strategy, "seed": seed, "steps": trainer.step, "train_seconds": train_s,
            "per_image": per_image, "grid": grids[SET]}


def _mean(v) -> float | None:
    return None if not v or any(x is None for x in v) else float(np.mean(v))


def report(runs: list[dict], args, root: Path) -> str:
    strategies = list(dict.fromkeys(r["strategy"] for r in runs))
    seeds = list(dict.fromkeys(r["seed"] for r in runs))
    by = {(r["strategy"], r["seed"]): {m: _mean(r["per_image"][m]) for m in METRICS} for r in runs}
    runs_by = {(r["strategy"], r["seed"]): r for r in runs}
    n_img = len(runs[0]["per_image"]["psnr_bbox"])
    lines = [f"# Vocabulary strategies on novel poses: {args.iterations} steps each, seeds "
             f"{', '.join(map(str, seeds))}", "",
             f"Capture {root}; set `{SET}`: {n_img} images per run (novel frames x evaluation "
             "views, the same images for every run). Cells: mean over seeds of each run's mean "
             "(spread over seeds = max - min).", "",
             "| strategy | " + " | ".join(METRICS) + " | per seed PSNR |", "|---" * (len(METRICS) + 2) + "|"]
    for s in strategies:
        cells = []
        for m in METRICS:
            v = [by[(s, k)][m] for k in seeds if (s, k) in by]
            cells.append("n/a" if any(x is None for x in v) else
                         f"{np.mean(v):.4f} ({max(v) - min(v):.4f})")
        per_seed = ", ".join(f"{by[(s, k)]['psnr_bbox']:.2f}" for k in seeds if (s, k) in by)
        lines.append(f"| {s} | " + " | ".join(cells) + f" | {per_seed} |")
    if "part" in strategies and len(seeds) > 1:
        lines += ["", "## Paired differences, part - other (same seed, same images)", "",
                  "Per seed, then mean [min, max] over seeds. Positive PSNR/SSIM and negative "
                  "LPIPS favour part; a range containing 0 is not resolved.", "",
                  "| part - | " + " | ".join(METRICS) + " | per seed PSNR |",
                  "|---" * (len(METRICS) + 2) + "|"]
        for other in (s for s in strategies if s != "part"):
            cells = []
            pairs = [k for k in seeds if ("part", k) in by and (other, k) in by]
            for m in METRICS:
                d = [by[("part", k)][m] - by[(other, k)][m] for k in pairs
                     if by[("part", k)][m] is not None and by[(other, k)][m] is not None]
                cells.append("n/a" if not d else f"{np.mean(d):+.4f} [{min(d):+.4f}, {max(d):+.4f}]")
            per_seed = ", ".join(f"{by[('part', k)]['psnr_bbox'] - by[(other, k)]['psnr_bbox']:+.2f}"
                                 for k in pairs)
            lines.append(f"| {other} | " + " | ".join(cells) + f" | {per_seed} |")
        lines += ["", "Per image (all seeds pooled): mean PSNR difference part - other ± its "
                  "standard error over the seed x image pairs, and the share of pairs where "
                  "part is better.", "", "| part - | d PSNR (dB) | part better |", "|---|---|---|"]
        for other in (s for s in strategies if s != "part"):
            d = np.concatenate([np.subtract(runs_by[("part", k)]["per_image"]["psnr_bbox"],
                                            runs_by[(other, k)]["per_image"]["psnr_bbox"])
                                for k in seeds if ("part", k) in runs_by and (other, k) in runs_by])
            lines.append(f"| {other} | {d.mean():+.3f} ± {d.std(ddof=1) / np.sqrt(len(d)):.3f} "
                         f"(n = {len(d)}) | {(d > 0).mean():.0%} |")
    return "\n".join(lines) + "\n"


def side_by_side(runs: list[dict], out: Path) -> Path | None:
    """truth | one column per strategy (the first seed's run), the same novel frames."""
    first = {}
    for r in runs:
        first.setdefault(r["strategy"], r)
    if not first:
        return None
    strategies = list(first)
    n = min(len(first[s]["grid"]) for s in strategies)
    rows = [[first[strategies[0]]["grid"][i][0]] + [first[s]["grid"][i][1] for s in strategies]
            for i in range(n)]
    seed = next(iter(first.values()))["seed"]
    return save_png(out / "side_by_side.png",
                    contact_sheet(rows, col_labels=["truth"] + [f"{s} (seed {seed})" for s in strategies]))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("capture", nargs="?", default=None, help="capture folder (default: synthesise)")
    ap.add_argument("--motion", choices=("compositional", "default"), default="compositional",
                    help="motion of the synthesised capture (without CAPTURE)")
    ap.add_argument("--iterations", type=int, default=300, help="training steps per run")
    ap.add_argument("--strategies", nargs="+", default=["part", "joint", "global", "none"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--per-set", type=int, default=10,
                    help="novel frames evaluated (evenly spread; x every evaluation view); "
                         "0: every novel frame")
    ap.add_argument("--grid-rows", type=int, default=3, help="novel images in side_by_side.png")
    ap.add_argument("--preset", choices=("fast", "balanced", "quality"), default="fast",
                    help="render preset for evaluation (render knobs only)")
    ap.add_argument("--out", default="out/bench/strategies")
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--report-only", action="store_true",
                    help="rewrite strategies.md from OUT/strategies.json (no training)")
    args = ap.parse_args(argv)
    args.per_set = args.per_set or None
    if args.report_only:
        out = Path(args.out)
        runs = json.loads((out / "strategies.json").read_text())
        md = report(runs, args, Path(args.capture or out / f"capture_{args.motion}"))
        atomic_write_bytes(out / "strategies.md", lambda t: Path(t).write_text(md))
        print(md)
        return 0

    out = Path(args.out)
    root = Path(args.capture) if args.capture else make_capture(out, args.motion)
    runs = [train_and_evaluate(root, s, seed, args) for seed in args.seeds for s in args.strategies]
    md = report(runs, args, root)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(out / "strategies.md", lambda t: Path(t).write_text(md))
    blob = json.dumps([{k: v for k, v in r.items() if k != "grid"} for r in runs], indent=1)
    atomic_write_bytes(out / "strategies.json", lambda t: Path(t).write_text(blob))
    sheet = side_by_side(runs, out)
    print(md)
    print(f"side by side: {sheet}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
