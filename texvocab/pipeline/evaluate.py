"""``texvocab eval``: render held-out views on training poses and on novel poses, compare
with ground truth, write a Markdown + JSON table and an image grid (truth | render |
error).

Protocols (see texvocab.metrics): PSNR/SSIM inside the mask's bounding box (AniNeRF
style) and on the full frame; LPIPS (VGG, on the box crop) when its weights exist; FID
(from 50 images per set) and KID (from 2) between all true and rendered images of a set
when the Inception extractor exists. Every mean comes with its standard error and the
image count; by default the sets are the whole test split (:func:`build_sets`).
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from texvocab.body.poses import preset
from texvocab.capture.fold_regions import FoldRegions
from texvocab.capture.synth import ground_truth_renderer
from texvocab.errors import TexvocabError
from texvocab.io.images import atomic_write_bytes, contact_sheet, save_png
from texvocab.metrics import evaluate_pair, frechet
from texvocab.metrics.fold_region import fold_region_metrics, summarise_fold
from texvocab.metrics.image import SSIM_WINDOW
from texvocab.pipeline.split import one_camera, scored_views
from texvocab.render import prepare_shell, render_image

#: Per-image metrics whose set mean is reported with its standard error.
SEM_KEYS = ("psnr_bbox", "ssim_bbox", "psnr_full", "ssim_full", "lpips", "iou")
#: Default generated novel poses of synthetic captures (texvocab.body.poses presets).
GENERATED_POSES = ("kick", "squat", "arms_up", "a_pose")

# (pose (24, 3), trans (3,), Camera, truth (H, W, 3) float in [0, 1], mask (H, W) bool)
log = logging.getLogger("texvocab")
Item = tuple[np.ndarray, np.ndarray, object, np.ndarray, np.ndarray]


def render_view(model, pose, trans, camera, march, scale: float = 1.0):
    """(H, W, 3) float32 render of the avatar at a pose from a camera, and RenderStats.

    ``scale`` < 1 renders ``camera.scaled(scale)`` (the ``image_scale`` knob) and resizes
    the result bilinearly to the camera's full size, as a viewer would show it."""
    rgb, _, stats = render_view_rgba(model, pose, trans, camera, march, scale)
    return rgb, stats


def render_view_rgba(model, pose, trans, camera, march, scale: float = 1.0):
    """:func:`render_view` with the opacity: (rgb (H, W, 3), alpha (H, W), RenderStats)."""
    t0 = time.perf_counter()
    with torch.no_grad():
        ctx = model.pose_feature.context(pose, trans)
        shell = prepare_shell(march, ctx.vertices, model.body.faces, ctx.index)  # its path's
        cam = camera if scale == 1.0 else camera.scaled(scale)
        field = model.for_pose(ctx, march.precision)
        out = render_image(field, cam, ctx.vertices, model.body.faces, march, shell=shell, index=ctx.index)
        rgba = torch.cat([out.rgb, out.alpha[..., None]], -1)
        if scale != 1.0:
            rgba = (
                torch.nn.functional.interpolate(
                    rgba.permute(2, 0, 1)[None],
                    size=(camera.height, camera.width),
                    mode="bilinear",
                    align_corners=False,
                )[0]
                .permute(1, 2, 0)
                .clamp(0, 1)
            )
    out.stats.seconds = time.perf_counter() - t0  # incl. pose context and shell
    rgba = rgba.numpy().astype(np.float32)
    return rgba[..., :3], rgba[..., 3], out.stats


def silhouette_iou(alpha: np.ndarray, mask: np.ndarray) -> float | None:
    """IoU of the rendered silhouette (opacity > 0.5) (H, W) against the mask (H, W);
    None when both are empty."""
    pred, truth = alpha > 0.5, np.asarray(mask, bool)
    union = int((pred | truth).sum())
    return None if union == 0 else float((pred & truth).sum() / union)


def _error_image(pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """(H, W, 3) |pred - gt| averaged over channels, x4, clipped to [0, 1], grey."""
    err = np.abs(pred - gt).mean(-1, keepdims=True) * 4
    return np.clip(np.repeat(err, 3, -1), 0, 1)


def sem(values: Sequence[float]) -> float | None:
    """Standard error of the mean of ``values`` (n,): ``std(ddof=1) / sqrt(n)``; None for
    n < 2."""
    if len(values) < 2:
        return None
    return float(np.std(np.asarray(values, np.float64), ddof=1) / np.sqrt(len(values)))


def summarise(per: list[dict[str, float | None]]) -> dict[str, float | None]:
    """Set summary of per-image metric dicts: the mean of each metric and, for
    :data:`SEM_KEYS`, ``<metric>_sem`` (:func:`sem`). A metric that is None for some image
    (LPIPS without weights) is None, as is its sem."""
    keys = list(per[0]) if per else [*SEM_KEYS, "seconds"]
    out: dict[str, float | None] = {}
    for k in keys:
        vals = [p.get(k) for p in per]
        ok = bool(vals) and all(v is not None for v in vals)
        out[k] = float(np.mean(vals)) if ok else None
        if k in SEM_KEYS:
            out[f"{k}_sem"] = sem(vals) if ok else None
    return out


class _PairFeatures:
    """Inception features of a set's (truth, render) pairs, computed ``FID_BATCH`` images at
    a time while the set renders (nothing is kept but the (2N, 2048) features)."""

    def __init__(self, extractor):
        self.extractor, self.pending, self.chunks = extractor, [], []

    def add(self, gt: np.ndarray, pred: np.ndarray) -> None:
        if self.extractor is None:
            return
        self.pending += [gt, pred]
        if len(self.pending) >= frechet.FID_BATCH:
            self.flush()

    def flush(self) -> None:
        if self.pending:
            self.chunks.append(frechet.inception_features(self.pending, self.extractor))
            self.pending = []

    def scores(self) -> dict[str, float | None]:
        """``{"fid", "kid", "kid_std"}`` (frechet.scores_from_features); None without an
        extractor."""
        self.flush()
        if self.extractor is None or not self.chunks:
            return {"fid": None, "kid": None, "kid_std": None}
        f = np.concatenate(self.chunks)  # rows alternate truth, render
        return frechet.scores_from_features(f[0::2], f[1::2])


def evaluate_sets(
    model,
    sets: dict[str, Sequence[Item]],
    march,
    lpips_model=None,
    grid_rows: int = 4,
    scale: float = 1.0,
    progress: bool = True,
) -> tuple[dict[str, dict], list[dict], dict[str, list]]:
    """Render and score every item of every set. ``sets``: name -> sequence of items
    (pose (24, 3), trans (3,), camera, gt (H, W, 3), mask (H, W)); renders at ``scale`` of
    each camera's size (see :func:`render_view`). ``progress``: a tqdm bar over all images
    on stderr.

    Returns (table, records, grids): table {name: :func:`summarise` of the per-image
    metrics + ``fid``, ``kid``, ``kid_std`` (frechet.scores_from_features: FID from 50
    images, KID from 2, None without the Inception extractor) + ``images`` (N)}; one
    record per image ({set, index[, frame, view], metrics}); grid rows
    [truth, render, error] (the first ``grid_rows`` items) per set.
    """
    extractor = frechet.inception_extractor() if any(len(v) >= 2 for v in sets.values()) else None
    table, records, grids = {}, [], {}
    with tqdm(total=sum(len(v) for v in sets.values()), desc="eval", unit="img", disable=not progress) as bar:
        for name, items in sets.items():
            bar.set_postfix_str(name)
            pairs = getattr(items, "pairs", None)
            feats = _PairFeatures(extractor if len(items) >= 2 else None)
            # synthetic captures: metrics on the pixels whose truth changes with pose
            folds = FoldRegions.load(items.capture.root) if pairs and hasattr(items, "capture") else None
            per, rows, fold_per = [], [], []
            for i, (pose, trans, cam, gt, mask) in enumerate(items):
                pred, alpha, stats = render_view_rgba(model, pose, trans, cam, march, scale)
                m = evaluate_pair(pred, gt, mask, lpips_model=lpips_model)
                m["iou"] = silhouette_iou(alpha, mask)
                m["seconds"] = stats.seconds
                if folds is not None:
                    region = folds.region(*pairs[i])
                    fold_per.append(None if region is None else fold_region_metrics(pred, gt, region, alpha))
                    m.update(fold_per[-1] or {})
                per.append(m)
                where = {"frame": int(pairs[i][0]), "view": int(pairs[i][1])} if pairs else {}
                records.append({"set": name, "index": i, **where, **m})
                feats.add(gt, pred)
                if len(rows) < grid_rows:
                    rows.append([gt, pred, _error_image(pred, gt)])
                bar.update()
            bar.set_postfix_str(f"{name}: FID/KID")
            table[name] = {**summarise(per), **feats.scores(), "images": len(per)}
            if folds is not None:
                table[name].update(summarise_fold(fold_per))
            if getattr(items, "label", None):  # e.g. "seen view" (texvocab.pipeline.split)
                table[name]["views"] = items.label
            grids[name] = rows
    return table, records, grids


def _cell(row: dict, key: str, digits: int) -> str:
    """``mean ± sem`` of ``row[key]`` with ``digits`` decimals (mean alone without a sem)."""
    v, s = row.get(key), row.get(f"{key}_sem")
    if v is None:
        return "n/a"
    return f"{v:.{digits}f}" + ("" if s is None else f" ± {s:.{digits}f}")


def _score_cell(row: dict, key: str, need: int, digits: int) -> str:
    """FID / KID cell: the value (KID with its std over subsets when subsampled), or
    ``n/a (N images)`` when the set has fewer than ``need`` images, else ``n/a``."""
    v, n = row.get(key), int(row.get("images", 0))
    if v is None:
        return f"n/a ({n} image{'s' if n != 1 else ''})" if n < need else "n/a"
    std = row.get(f"{key}_std")
    return f"{v:.{digits}f}" + ("" if std is None else f" (sd {std:.{digits}f})")


def format_table(table: dict[str, dict], checkpoint: str = "", split: str = "") -> str:
    """metrics.md: the header says what ± means (and ``split``, what is held out); one
    row per set with its image count, labelled with its views when they are not held out
    (``views``: "seen view" ...)."""
    lines = [
        f"# texvocab eval: {checkpoint} (mean ± standard error of the mean, std/√n)",
        "",
        "Each cell is the mean over the set's n images ± its standard error (sample std "
        "with ddof 1 / √n; it treats the images as independent, but the views of one frame "
        "and neighbouring frames are correlated, so it likely understates the spread). "
        "PSNR (dB) / SSIM inside the mask bounding box (AniNeRF style) and on the full "
        "frame; LPIPS (VGG, box crop) when its weights exist; FID (from "
        f"{frechet.FID_MIN_IMAGES} images per set) and KID (unbiased, polynomial kernel, "
        "from 2 images; sd = std over random subsets when the set is subsampled) between "
        "the set's true and rendered images when the Inception extractor is installed, "
        "else n/a; iou: the rendered silhouette (opacity > 0.5) against the mask; "
        "seconds: mean render time per image.",
        "",
        *([f"Split: {split}.", ""] if split else []),
        "| set | images | psnr_bbox | ssim_bbox | psnr_full | ssim_full | lpips | fid | kid "
        "| iou | seconds |",
        "|---" * 11 + "|",
    ]
    for name, row in table.items():
        cells = [
            str(row.get("images", 0)),
            _cell(row, "psnr_bbox", 2),
            _cell(row, "ssim_bbox", 4),
            _cell(row, "psnr_full", 2),
            _cell(row, "ssim_full", 4),
            _cell(row, "lpips", 4),
            _score_cell(row, "fid", frechet.FID_MIN_IMAGES, 2),
            _score_cell(row, "kid", 2, 4),
            _cell(row, "iou", 3),
            _cell(row, "seconds", 2),
        ]
        shown = f"{name} ({row['views']})" if row.get("views") else name
        lines.append(f"| {shown} | " + " | ".join(cells) + " |")
    folds = [(name, row) for name, row in table.items() if "fold_images" in row]
    if folds:  # texvocab.metrics.fold_region
        lines += ["", "Fold regions (pixels whose truth changes with pose):", ""]
        lines += [
            "| set | images | psnr_fold | ssim_fold | psnr_fold drawn | fold empty |",
            "|---|---|---|---|---|---|",
        ]
        for name, row in folds:
            cells = [
                str(row["fold_images"]),
                _cell(row, "psnr_fold", 2),
                _cell(row, "ssim_fold", 4),
                _cell(row, "psnr_fold_drawn", 2),
                _cell(row, "fold_empty", 3),
            ]
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def write_report(out_dir: Path, table: dict, records: list, grids: dict, meta: dict) -> list[Path]:
    """metrics.md (:func:`format_table`), metrics.json ({meta, protocol, table, images}) and
    grid_<set>.png under ``out_dir``; returns their paths, metrics.md first."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    md = format_table(table, str(meta.get("checkpoint", "")), str(meta.get("split", "")))
    paths = [atomic_write_bytes(out_dir / "metrics.md", lambda t: Path(t).write_text(md))]
    protocol = {
        "sem": "std(ddof=1) / sqrt(images), in <metric>_sem",
        "fid_min_images": frechet.FID_MIN_IMAGES,
        "kid": "unbiased MMD^2, kernel (x.y/d + 1)^3; kid_std over random subsets of "
        f"{frechet.KID_SUBSET_SIZE} when a set is larger, else null",
    }
    blob = json.dumps({"meta": meta, "protocol": protocol, "table": table, "images": records}, indent=1)
    paths.append(atomic_write_bytes(out_dir / "metrics.json", lambda t: Path(t).write_text(blob)))
    for name, rows in grids.items():
        if rows:
            paths.append(
                save_png(
                    out_dir / f"grid_{name}.png",
                    contact_sheet(rows, col_labels=["truth", "render", "|error| x4"]),
                )
            )
    return paths


class CaptureItems(Sequence):
    """Evaluation items of a capture's (frame, view) ``pairs``, read from disk when indexed
    (a full test split of a real capture is never held in memory at once). ``label``: what
    the views are when they are not held out ("seen view"), for the report."""

    def __init__(self, capture, pairs: Sequence[tuple[int, int]], label: str | None = None):
        self.capture, self.pairs = capture, [(int(t), int(v)) for t, v in pairs]
        self.label = label

    def __len__(self) -> int:
        return len(self.pairs)

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        t, v = self.pairs[i]
        c = self.capture
        return (c.poses[t], c.trans[t], c.cameras[v], c.image(v, t), c.mask(v, t))


def spread(frames: Sequence[int], n: int) -> list[int]:
    """``min(n, len(frames))`` of ``frames``, evenly spread from the first to the last."""
    frames = list(frames)
    n = min(n, len(frames))
    if n <= 0:
        return []
    return sorted({frames[int(i)] for i in np.linspace(0, len(frames) - 1, n)})


def build_sets(
    capture, settings, per_set: int | None = None, generated: tuple[str, ...] = GENERATED_POSES
) -> dict[str, Sequence[Item]]:
    """Evaluation sets of items (pose, trans, camera, gt (H, W, 3), mask (H, W)), each frame
    seen from every view of ``settings.data.eval_views`` (a one-camera capture: from its camera,
    the training poses labelled "seen view"; :mod:`texvocab.pipeline.split`):

    - ``novel_poses``: every novel frame (``per_set``: that many, evenly spread);
    - ``training_poses``: as many training frames as novel ones, evenly spread over the
      training frames (all of them, or ``per_set``, when the capture has no novel frames);
    - ``generated_novel_poses`` (synthetic captures): the ``generated`` preset poses
      rendered as ground truth.

    Capture sets are :class:`CaptureItems` (images read when indexed). TexvocabError when
    ``per_set`` < 1.
    """
    if per_set is not None and per_set < 1:
        raise TexvocabError(f"--per-set must be at least 1, got {per_set}")
    views = scored_views(capture, settings.data.eval_views)
    labels = (
        {"training_poses": "seen view", "novel_poses": "capture camera, held-out frames"}
        if one_camera(capture)
        else {}
    )
    small = [v for v in views if min(capture.cameras[v].width, capture.cameras[v].height) < SSIM_WINDOW]
    if small:
        cam = capture.cameras[small[0]]
        raise TexvocabError(
            f"{capture.root}: view {small[0]} is {cam.width}x{cam.height} "
            f"pixels; SSIM needs at least {SSIM_WINDOW}x{SSIM_WINDOW}"
        )
    novel, train = list(capture.novel_frames), list(capture.train_frames)
    n_novel = len(novel) if per_set is None else min(per_set, len(novel))
    n_train = n_novel if novel else (len(train) if per_set is None else per_set)
    sets: dict[str, Sequence[Item]] = {}
    for name, frames in (("training_poses", spread(train, n_train)), ("novel_poses", spread(novel, n_novel))):
        pairs = [(t, v) for t in frames for v in views]
        empty = [(t, v) for t, v in pairs if not capture.mask(v, t).any()]
        if empty:
            log.warning(
                "%s: %d of %d images have an empty mask (first: frame %d, view %d) "
                "and are left out: their metrics are undefined",
                name,
                len(empty),
                len(pairs),
                capture.frame_ids[empty[0][0]],
                empty[0][1],
            )
            pairs = [p for p in pairs if p not in empty]
        if pairs:
            sets[name] = CaptureItems(capture, pairs, labels.get(name))
    if capture.synthetic and generated:
        renderer, cams = ground_truth_renderer(capture)
        items = []
        for name in generated:
            pose, trans = preset(name)
            truths = renderer.render(pose, trans, [cams[v] for v in views])
            items += [(pose, trans, cams[v], rgb, mask) for v, (rgb, mask) in zip(views, truths, strict=True)]
        renderer.close()
        sets["generated_novel_poses"] = items
    return sets
