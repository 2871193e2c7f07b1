"""``texvocab demo``: what exists so far — the body (default or the user's SMPL) in six
poses, rendered offscreen front and side, and the default synthetic capture (views ×
frames contact sheet), written as PNGs."""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np

from texvocab.body import load_body
from texvocab.body.poses import preset
from texvocab.capture import open as open_capture
from texvocab.capture.motion import default_motion
from texvocab.capture.synth import synthesize
from texvocab.errors import TexvocabError
from texvocab.io.images import contact_sheet, save_png
from texvocab.pipeline.evaluate import build_sets, evaluate_sets, write_report
from texvocab.pipeline.settings import Settings, TrainSettings, march_settings
from texvocab.pipeline.train import Trainer

log = logging.getLogger("texvocab")

DEMO_POSES = ("t_pose", "arms_down", "walk", "squat", "arms_up", "kick")


def render_pose_sheet(body, size: int = 320, poses=DEMO_POSES) -> tuple[np.ndarray, dict]:
    """Contact sheet (uint8) with one row per view (front, side) and one column per pose.

    Returns the sheet and the individual renders {(pose, view): rgb float (H, W, 3)}.
    """
    # late: mesh_renderer imports pyrender, binding PyOpenGL to OSMesa (texvocab.io.gl_platform)
    from texvocab.capture.mesh_renderer import MeshRenderer, intrinsics, look_at

    K = intrinsics(size, size, fov_y_deg=40.0)
    views = {
        "front": look_at((0, -0.25, 3.6), (0, -0.25, 0)),
        "side": look_at((3.6, -0.25, 0), (0, -0.25, 0)),
    }
    renders: dict[tuple[str, str], np.ndarray] = {}
    with MeshRenderer(size, size) as renderer:
        for name in poses:
            pose, trans = preset(name)
            out = body.forward(pose[None], trans[None])
            verts = out.vertices[0].numpy()
            for view, (R, t) in views.items():
                renders[(name, view)], _ = renderer.render(verts, body.faces.numpy(), K, R, t)
    rows = [[renders[(p, v)] for p in poses] for v in views]
    return contact_sheet(rows, row_labels=list(views), col_labels=list(poses)), renders


def run_demo(out_dir: str | Path, smpl: str | None = None, size: int = 320) -> list[Path]:
    """Write the body-pose PNGs under ``out_dir``; return their paths (sheet first)."""
    out_dir = Path(out_dir)
    body = load_body(smpl)
    sheet, renders = render_pose_sheet(body, size)
    written = [save_png(out_dir / "poses.png", sheet)]
    for (pose, view), rgb in renders.items():
        written.append(save_png(out_dir / "poses" / f"{pose}_{view}.png", rgb))
    return written


def demo_capture(
    out_dir: str | Path, smpl: str | None = None, frames: int | None = None
) -> tuple[Path, Path]:
    """Synthesise the default capture under ``out_dir/capture`` (reused when present) and
    write its contact sheet; returns (capture folder, sheet path)."""
    out_dir = Path(out_dir)
    root = out_dir / "capture"
    body = load_body(smpl)
    if not root.exists():
        poses, trans, num_train = default_motion(0)
        if frames:
            poses, trans, num_train = poses[:frames], trans[:frames], min(num_train, frames)
        synthesize(root, poses, trans, num_train, body, body_source=smpl or "default")
    cap = open_capture(root, body=body)
    picks = sorted(set(np.linspace(0, cap.num_frames - 1, min(8, cap.num_frames)).astype(int)))
    rows = [[cap.image(v, t) for t in picks] for v in range(cap.num_views)]
    labels = [f"{'train' if t < cap.num_train else 'novel'} {t}" for t in picks]
    sheet = save_png(
        out_dir / "capture_sheet.png", contact_sheet(rows, [c.name for c in cap.cameras], labels)
    )
    return root, sheet


def demo_avatar(
    out_dir: str | Path, capture_root: Path, minutes: float = 3.0, smpl: str | None = None
) -> tuple[Path, Path]:
    """Prepare texture maps, train a short avatar (``minutes`` of wall time, resumed on
    later runs until it has had that long) and evaluate it on the full default test sets
    (every novel frame and as many training frames, each from every evaluation view, with
    a progress bar); returns (checkpoint, report)."""
    run = Path(out_dir) / "avatar"
    cap = open_capture(capture_root, body=load_body(smpl))
    settings = Settings(train=TrainSettings(iterations=100000, max_minutes=minutes, checkpoint_every=100))
    trainer = Trainer(cap, settings, run)
    try:
        trainer.resume()
    except TexvocabError as e:  # the demo's own run, from other settings (an older texvocab)
        kept = run / f"checkpoint-before-{time.strftime('%Y%m%d-%H%M%S')}.pt"
        trainer.checkpoint_path.rename(kept)
        log.warning("%s; kept it as %s and training the demo avatar afresh", e, kept)
    trainer.run()
    trainer.model.eval()
    settings = trainer.s  # with the field's shell fitted to the masks (field.shell_coverage)
    sets = build_sets(cap, settings)  # the full test split: every novel frame x eval view
    table, records, grids = evaluate_sets(trainer.model, sets, march_settings(settings), progress=True)
    paths = write_report(
        run / "eval",
        table,
        records,
        grids,
        {
            "checkpoint": str(trainer.checkpoint_path),
            "step": trainer.step,
            "capture": str(capture_root),
            "settings": settings.to_dict(),
        },
    )
    return trainer.checkpoint_path, paths[0]
