"""``texvocab eval``: render held-out views on training poses and on novel poses, compare
with ground truth, write a Markdown + JSON table and an image grid (truth | render |
error).

Protocols (see texvocab.metrics): PSNR/SSIM inside the mask's bounding box (AniNeRF
style) and on the full frame; LPIPS (VGG, on the box crop) when its weights exist; FID
over all rendered vs true images of a set when the Inception extractor exists.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import torch

from texvocab.imageio import atomic_write_bytes, contact_sheet, save_png
from texvocab.metrics import evaluate_pair
from texvocab.render import ShellGeometry, render_image


def render_view(model, pose, trans, camera, march, scale: float = 1.0):
    """(H, W, 3) float32 render of the avatar at a pose from a camera, and RenderStats.

    ``scale`` < 1 renders ``camera.scaled(scale)`` (the ``image_scale`` knob) and resizes
    the result bilinearly to the camera's full size, as a viewer would show it."""
    t0 = time.perf_counter()
    with torch.no_grad():
        ctx = model.pose_feature.context(pose, trans)
        shell = ShellGeometry.build(ctx.vertices, model.body.faces, march.shell_width,
                                    march.shell_voxel, march.shell_exact, index=ctx.index)
        cam = camera if scale == 1.0 else camera.scaled(scale)
        out = render_image(model.for_pose(ctx), cam, ctx.vertices, model.body.faces, march,
                           shell=shell)
        rgb = out.rgb
        if scale != 1.0:
            rgb = torch.nn.functional.interpolate(
                rgb.permute(2, 0, 1)[None], size=(camera.height, camera.width), mode="bilinear",
                align_corners=False)[0].permute(1, 2, 0).clamp(0, 1)
    out.stats.seconds = time.perf_counter() - t0  # incl. pose context and shell
    return rgb.numpy().astype(np.float32), out.stats


def _error_image(pred, gt):
    err = np.abs(pred - gt).mean(-1, keepdims=True) * 4
    return np.clip(np.repeat(err, 3, -1), 0, 1)


def evaluate_sets(model, sets: dict, march, lpips_model=None, grid_rows: int = 4,
                  scale: float = 1.0):
    """sets: name -> list of (pose, trans, camera, gt (H, W, 3), mask (H, W)); renders at
    ``scale`` of each camera's size (see :func:`render_view`).

    Returns (table {name: mean metrics}, per-image records, grid rows per set).
    """
    from texvocab.metrics import fid

    table, records, grids = {}, [], {}
    for name, items in sets.items():
        rows, preds, gts = [], [], []
        per = []
        for i, (pose, trans, cam, gt, mask) in enumerate(items):
            pred, stats = render_view(model, pose, trans, cam, march, scale)
            m = evaluate_pair(pred, gt, mask, lpips_model=lpips_model)
            m["seconds"] = stats.seconds
            per.append(m)
            records.append({"set": name, "index": i, **m})
            preds.append(pred)
            gts.append(gt)
            if len(rows) < grid_rows:
                rows.append([gt, pred, _error_image(pred, gt)])
        mean = {k: float(np.mean([p[k] for p in per])) for k in per[0]
                if per[0][k] is not None}
        mean["fid"] = fid(np.stack(gts), np.stack(preds)) if len(gts) >= 2 else None
        mean["images"] = len(per)
        table[name] = mean
        grids[name] = rows
    return table, records, grids


def write_report(out_dir: Path, table: dict, records: list, grids: dict, meta: dict) -> list[Path]:
    """metrics.json, metrics.md and grid_<set>.png under ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    cols = ["psnr_bbox", "ssim_bbox", "psnr_full", "ssim_full", "lpips", "fid", "seconds",
            "images"]
    lines = [f"# texvocab eval: {meta.get('checkpoint', '')}", "",
             "PSNR/SSIM inside the mask bounding box (AniNeRF style) and on the full frame; "
             "LPIPS (VGG, box crop) and FID when their weights exist (else n/a).", "",
             "| set | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for name, row in table.items():
        vals = []
        for c in cols:
            v = row.get(c)
            vals.append("n/a" if v is None else (f"{v:.4f}" if isinstance(v, float) else str(v)))
        lines.append(f"| {name} | " + " | ".join(vals) + " |")
    md = "\n".join(lines) + "\n"
    paths = [atomic_write_bytes(out_dir / "metrics.md", lambda t: Path(t).write_text(md))]
    blob = json.dumps({"meta": meta, "table": table, "images": records}, indent=1)
    paths.append(atomic_write_bytes(out_dir / "metrics.json", lambda t: Path(t).write_text(blob)))
    for name, rows in grids.items():
        if rows:
            paths.append(save_png(out_dir / f"grid_{name}.png",
                                  contact_sheet(rows, col_labels=["truth", "render", "|error| x4"])))
    return paths


def build_sets(capture, settings, per_set: int = 4, generated: tuple[str, ...] = (
        "kick", "squat", "arms_up", "a_pose")) -> dict:
    """Evaluation sets: held-out views on training poses, on novel frames, and (synthetic
    captures) on generated novel poses rendered as ground truth."""
    views = list(settings.eval_views)

    def frames_of(rng_frames):
        frames = list(rng_frames)
        if not frames:
            return []
        return sorted({frames[int(i)] for i in np.linspace(0, len(frames) - 1, per_set)})

    sets = {}
    for name, frames in (("training_poses", frames_of(capture.train_frames)),
                         ("novel_poses", frames_of(capture.novel_frames))):
        items = [(capture.poses[t], capture.trans[t], capture.cameras[v], capture.image(v, t),
                  capture.mask(v, t)) for t in frames for v in views]
        if items:
            sets[name] = items
    if capture.synthetic and generated:
        from texvocab.body.poses import preset
        from texvocab.capture.synth import ground_truth_renderer

        renderer, cams = ground_truth_renderer(capture)
        items = []
        for name in generated:
            pose, trans = preset(name)
            truths = renderer.render(pose, trans, [cams[v] for v in views])
            items += [(pose, trans, cams[v], rgb, mask)
                      for v, (rgb, mask) in zip(views, truths, strict=True)]
        renderer.close()
        sets["generated_novel_poses"] = items
    return sets
