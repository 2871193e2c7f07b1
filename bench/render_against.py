"""Render speed against another version of texvocab, in one run: today's default render
path beside the default path of an older checkout, on the same checkpoint and frames.

    git worktree add OLD <commit>
    .venv/bin/python bench/render_against.py CKPT OLD [--frames 3] [--repeats 3] [--size N]

``bench/render_speed.py --compare`` keeps a ``previous`` path inside today's code, and it
shares everything the speed work did not switch off (the compiled raster, the plan, the
pose context). This bench instead times OLD's own code: a worker process
(``bench/render_against_worker.py``) imports OLD's ``texvocab`` and OLD's
``bench/render_speed.py`` and renders with OLD's default guided path (the surface-guided
marcher at OLD's ``fast`` preset), while this process renders with today's (the same at
today's ``fast`` preset). The two take turns frame by frame, never at once, so both see
the same load; each path keeps its best of ``--repeats`` per frame, after one warm-up
render of every frame on each side. CKPT must load in both versions: train it with OLD
(today's code loads older checkpoints).

Prints a table (per frame: seconds, field evaluations, PSNR against the truth in the
mask's bounding box, and between the two images) and as its last line
``summary: new_s=… baseline_s=… speedup=… new_evals=… baseline_evals=…
psnr_delta_db=… frames=… baseline=<OLD's commit>`` (per-frame means; speedup =
baseline_s / new_s; psnr_delta_db the new path's PSNR against the truth minus OLD's).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # before torch loads OpenMP

import numpy as np  # noqa: E402
import render_speed as rs  # noqa: E402
import torch  # noqa: E402

WORKER = Path(__file__).with_name("render_against_worker.py")


def tree_commit(tree: Path) -> str:
    """OLD's short commit, or "unknown" when it is not a git checkout."""
    try:
        cmd = ["git", "-C", str(tree), "rev-parse", "--short", "HEAD"]
        return subprocess.run(cmd, capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


class Baseline:
    """OLD's worker: started, waited for, asked to render frame ``i``, stopped."""

    def __init__(self, tree: Path, ckpt: str, frames: int, size: int, out: Path):
        env = {**os.environ, "PYTHONPATH": str(tree)}
        cmd = [sys.executable, str(WORKER), str(tree), ckpt, str(frames), str(size), str(out)]
        self.proc = subprocess.Popen(cmd, env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        line = self.proc.stdout.readline()
        if not line.startswith("ready "):
            self.proc.kill()
            raise SystemExit(f"error: {tree}: its code did not load {ckpt} (worker exit {self.proc.wait()})")
        self.labels = json.loads(line.removeprefix("ready "))

    def render(self, i: int) -> tuple[float, int]:
        self.proc.stdin.write(f"{i}\n")
        self.proc.stdin.flush()
        seconds, evals = self.proc.stdout.readline().split()
        return float(seconds), int(evals)

    def close(self) -> None:
        self.proc.stdin.write("\n")
        self.proc.stdin.close()
        self.proc.wait(timeout=60)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("checkpoint")
    ap.add_argument("baseline", type=Path, help="a checkout of texvocab at another commit (git worktree add)")
    ap.add_argument("--frames", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--size", type=int, default=0, help="render at N x N (the cameras scaled)")
    args = ap.parse_args(argv)
    tree = args.baseline.resolve()
    if not all((tree / p).is_file() for p in ("texvocab/__init__.py", "bench/render_speed.py")):
        msg = f"error: {tree}: expected a texvocab checkout (texvocab/ and bench/render_speed.py)"
        print(msg, file=sys.stderr)
        return 2
    from texvocab.metrics import evaluate_pair, psnr
    from texvocab.metrics.image import crop_to_bbox, mask_bbox
    from texvocab.pipeline.settings import PRESETS, march_settings

    torch.set_num_threads(2)

    class Args:
        checkpoint, capture = args.checkpoint, None

    model, settings, cap, _ = rs.load(Args())
    items = rs.resized(rs.items_of(cap, settings, args.frames), args.size or None)
    knobs = [f"{k}={v}" for k, v in PRESETS["fast"].items() if k != "image_scale"]
    march = march_settings(settings.with_overrides(knobs + ["guide=raster"]))
    with tempfile.TemporaryDirectory() as tmp:
        old = Baseline(tree, args.checkpoint, args.frames, args.size, Path(tmp))
        if old.labels != [it[0] for it in items]:
            old.close()
            print(f"error: {tree}: its frames {old.labels} differ from today's", file=sys.stderr)
            return 2
        images = [rs.timed_render(model, it, march)[0] for it in items]  # warm-up
        best = {"new": [(np.inf, 0)] * len(items), "baseline": [(np.inf, 0)] * len(items)}
        for _ in range(max(args.repeats, 1)):
            for i, item in enumerate(items):
                img, row = rs.timed_render(model, item, march)
                if row["total"] < best["new"][i][0]:
                    best["new"][i], images[i] = (row["total"], int(row["evals"])), img
                sec, evals = old.render(i)
                best["baseline"][i] = min(best["baseline"][i], (sec, evals))
        old.close()
        old_images = [np.load(Path(tmp) / f"baseline_{i}.npy") for i in range(len(items))]
    commit = tree_commit(tree)
    print(f"# today's default render path against {tree} (commit {commit})\n")
    cam = items[0][3]
    print(f"{len(items)} frames at {cam.width}x{cam.height}, 2 threads, best of {args.repeats}\n")
    print(
        "| frame | new s | baseline s | new evals | baseline evals | new PSNR | baseline PSNR "
        "| new vs baseline |"
    )
    print("|---|---|---|---|---|---|---|---|")
    rows = []
    for i, (label, *_, gt, mask) in enumerate(items):
        p_new = evaluate_pair(images[i], gt, mask)["psnr_bbox"]
        p_old = evaluate_pair(old_images[i], gt, mask)["psnr_bbox"]
        box = mask_bbox(mask)
        p_pair = psnr(crop_to_bbox(images[i], box), crop_to_bbox(old_images[i], box))
        (s_new, e_new), (s_old, e_old) = best["new"][i], best["baseline"][i]
        rows.append((s_new, s_old, e_new, e_old, p_new, p_old))
        print(
            f"| {label} | {s_new:.3f} | {s_old:.3f} | {e_new:,} | {e_old:,} | "
            f"{p_new:.3f} | {p_old:.3f} | {min(p_pair, 99.0):.2f} dB |"
        )
    m = np.mean(np.array(rows, np.float64), 0)
    print(
        f"\nsummary: new_s={m[0]:.3f} baseline_s={m[1]:.3f} speedup={m[1] / m[0]:.2f} new_evals={m[2]:.0f} "
        f"baseline_evals={m[3]:.0f} psnr_delta_db={m[4] - m[5]:+.3f} frames={len(items)} baseline={commit}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
