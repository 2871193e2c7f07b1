"""Pose refinement against the truth: how far the poses a run trained with are from the
poses a synthetic capture's images show, before and after training.

A capture made with imperfect fits records the true SMPL parameters plus noise
(``texvocab synth --fit-noise-deg D --fit-noise-trans M``) and keeps the truth in its
``texvocab_synth.json`` for analysis only; no reader hands it to training. For each
checkpoint this reads the training frames' recorded poses, the run's refined ones (its
``pose_refinement`` state; a run without refinement keeps the recorded ones) and the
truth, and prints per run and per refinement mode (mean and spread over seeds):

- the rotation error in degrees against the true rotations, of the root (joint 0) and
  the mean over the other 23 joints, recorded -> refined;
- the root translation error in cm, recorded -> refined;
- the share of (frame, joint) rotations the refinement brought closer to the truth;
- the silhouette IoU of the posed body against the capture's masks (every ``--every``-th
  training frame, every camera), recorded -> refined, beside the truth's (on a painted
  capture, whose person is the body, the truth's IoU is 1 up to rasterisation).

Usage, with the training runs made by the ablation bench's refinement group::

    texvocab synth CAP --fit-noise-deg 3 --fit-noise-trans 0.015
    bench/ablation.py refinement --capture CAP --seeds 0 1 2 --iterations 800 --jobs 2 --out OUT
    bench/pose_refinement.py CAP OUT/runs/*/seed*/checkpoint.pt [--json FILE]
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
from pathlib import Path

import numpy as np

from texvocab.capture import open as open_capture
from texvocab.capture.silhouette import silhouette_fit
from texvocab.capture.synth_realism import rotation_error_deg
from texvocab.errors import AssetError
from texvocab.io.checkpoint import load_checkpoint
from texvocab.method.pose_refinement import refined_poses


def true_fit(cap) -> tuple[np.ndarray, np.ndarray]:
    """The capture's true (poses (T, 24, 3), trans (T, 3)); AssetError when its
    ``texvocab_synth.json`` keeps none (a capture without fit noise, or not synthetic)."""
    meta = cap.synthetic or {}
    if "true_poses" not in meta:
        raise AssetError(
            f"{cap.root}: texvocab_synth.json keeps no true_poses; make the capture with "
            "texvocab synth --fit-noise-deg D --fit-noise-trans M"
        )
    poses = np.asarray(meta["true_poses"], np.float64)
    return poses.reshape(len(poses), -1, 3), np.asarray(meta["true_trans"], np.float64)


def pose_errors(poses, trans, true_poses, true_trans) -> dict:
    """Errors of (poses (T, J, 3), trans (T, 3)) against the truth: ``root_deg`` (T,),
    ``joints_deg`` (T, J - 1), ``trans_cm`` (T,)."""
    rot = rotation_error_deg(np.asarray(poses, np.float64), true_poses[: len(poses)])
    return {
        "root_deg": rot[:, 0],
        "joints_deg": rot[:, 1:],
        "trans_cm": 100 * np.linalg.norm(np.asarray(trans) - true_trans[: len(trans)], axis=-1),
    }


def body_iou(cap, poses, trans, frames: list[int]) -> float:
    """Mean silhouette IoU of the body posed at ``poses[frames]`` against the masks of
    every camera."""
    ious = [
        silhouette_fit(
            cap.body, poses[frames], trans[frames], cam, (cap.mask(v, t) for t in frames), cap.shape()
        ).iou
        for v, cam in enumerate(cap.cameras)
    ]
    return float(np.mean(np.concatenate(ious)))


@functools.cache
def _capture_reference(capture: Path, every: int):
    """What every run on ``capture`` shares, computed once: (capture, true poses, true
    translations, the IoU frames, the recorded and the true poses' body IoU)."""
    cap = open_capture(capture)
    true_poses, true_trans = true_fit(cap)
    num = cap.num_train
    frames = list(range(0, num, every))
    recorded = (np.asarray(cap.poses[:num], np.float64), np.asarray(cap.trans[:num], np.float64))
    iou_recorded = body_iou(cap, *recorded, frames)
    iou_true = body_iou(cap, true_poses[:num], true_trans[:num], frames)
    return cap, true_poses, true_trans, frames, iou_recorded, iou_true


def analyse(capture: Path, checkpoint: Path, every: int) -> dict:
    """One run's row (see the module docstring)."""
    cap, true_poses, true_trans, frames, iou_recorded, iou_true = _capture_reference(Path(capture), every)
    ck = load_checkpoint(checkpoint)
    settings = ck["settings"]
    train = settings.get("train", settings)
    state = ck.get("pose_refinement")
    num = cap.num_train
    recorded = (np.asarray(cap.poses[:num], np.float64), np.asarray(cap.trans[:num], np.float64))
    refined = recorded if state is None else refined_poses(state, cap.poses, cap.trans)
    before = pose_errors(*recorded, true_poses, true_trans)
    after = pose_errors(*refined, true_poses, true_trans)
    rot_before = np.concatenate([before["root_deg"][:, None], before["joints_deg"]], 1)
    rot_after = np.concatenate([after["root_deg"][:, None], after["joints_deg"]], 1)
    return {
        "checkpoint": str(checkpoint),
        "mode": "off" if state is None else str(state["mode"]),
        "seed": int(train.get("seed", -1)),
        "step": int(ck["step"]),
        "frames": num,
        **{f"{k}_before": float(v.mean()) for k, v in before.items()},
        **{f"{k}_after": float(v.mean()) for k, v in after.items()},
        "improved": float((rot_after < rot_before - 1e-9).mean()) if state is not None else 0.0,
        # per joint (J,): mean error over the frames before and after, share brought closer
        "joint_deg_before": rot_before.mean(0).tolist(),
        "joint_deg_after": rot_after.mean(0).tolist(),
        "joint_improved": (rot_after < rot_before - 1e-9).mean(0).tolist(),
        "iou_frames": len(frames) * len(cap.cameras),
        "iou_recorded": iou_recorded,
        "iou_refined": body_iou(cap, *refined, frames) if state is not None else None,
        "iou_true": iou_true,
    }


def _spread(rows: list[dict], key: str, digits: int) -> str:
    v = [r[key] for r in rows if r[key] is not None]
    if not v:
        return "n/a"
    return f"{np.mean(v):.{digits}f}" + (f" ({max(v) - min(v):.{digits}f})" if len(v) > 1 else "")


def format_report(rows: list[dict]) -> str:
    """Markdown: one row per run, then per mode the mean over its runs (spread = max - min)."""
    lines = [
        "| mode | seed | steps | root ° recorded -> refined | joints ° | translation cm | "
        "rotations improved | body IoU recorded -> refined (truth) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in sorted(rows, key=lambda r: (r["mode"], r["seed"])):
        iou = "n/a" if r["iou_refined"] is None else f"{r['iou_refined']:.4f}"
        lines.append(
            f"| {r['mode']} | {r['seed']} | {r['step']} | {r['root_deg_before']:.2f} -> "
            f"{r['root_deg_after']:.2f} | {r['joints_deg_before']:.2f} -> {r['joints_deg_after']:.2f} | "
            f"{r['trans_cm_before']:.2f} -> {r['trans_cm_after']:.2f} | {r['improved']:.0%} | "
            f"{r['iou_recorded']:.4f} -> {iou} ({r['iou_true']:.4f}) |"
        )
    lines += [
        "",
        "| mode | runs | root ° after | joints ° after | translation cm after | body IoU refined |",
        "|---|---|---|---|---|---|",
    ]
    for mode in sorted({r["mode"] for r in rows}):
        group = [r for r in rows if r["mode"] == mode]
        cells = [_spread(group, k, d) for k, d in (("root_deg_after", 2), ("joints_deg_after", 2))]
        cells += [_spread(group, "trans_cm_after", 2), _spread(group, "iou_refined", 4)]
        lines.append(f"| {mode} | {len(group)} | " + " | ".join(cells) + " |")
    return "\n".join(lines + joint_table(rows)) + "\n"


def joint_table(rows: list[dict]) -> list[str]:
    """Markdown: per joint, the rotation error recorded -> refined (degrees, mean over the
    frames and the mode's runs) and the share of its frames brought closer, per mode that
    refines."""
    from texvocab.body import JOINT_NAMES

    modes = sorted({r["mode"] for r in rows} - {"off"})
    if not modes:
        return []
    lines = [
        "",
        "| joint | " + " | ".join(f"{m}: ° recorded -> refined | closer" for m in modes) + " |",
        "|---" * (1 + 2 * len(modes)) + "|",
    ]
    for j, name in enumerate(JOINT_NAMES):
        cells = []
        for m in modes:
            group = [r for r in rows if r["mode"] == m]
            before = np.mean([r["joint_deg_before"][j] for r in group])
            after = np.mean([r["joint_deg_after"][j] for r in group])
            closer = np.mean([r["joint_improved"][j] for r in group])
            cells += [f"{before:.2f} -> {after:.2f}", f"{closer:.0%}"]
        lines.append(f"| {j} {name} | " + " | ".join(cells) + " |")
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("capture", type=Path, help="a texvocab synth capture made with fit noise")
    ap.add_argument("checkpoints", type=Path, nargs="+", help="checkpoints trained on it")
    ap.add_argument("--every", type=int, default=5, help="training frames between IoU frames")
    ap.add_argument("--json", type=Path, default=None, help="also write the rows here")
    args = ap.parse_args(argv)
    try:
        rows = [analyse(args.capture, ck, args.every) for ck in args.checkpoints]
    except AssetError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(format_report(rows), end="")
    if args.json is not None:
        from texvocab.io.images import atomic_write_bytes

        blob = json.dumps(rows, indent=1)
        atomic_write_bytes(args.json, lambda t: Path(t).write_text(blob))
    return 0


if __name__ == "__main__":
    sys.exit(main())
