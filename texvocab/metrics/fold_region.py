"""Metrics on the pixels whose truth changes with pose (fold regions).

A synthetic capture stores, per novel frame and view, where its true image differs from
the same view rendered with the clothing's rest-pose folds
(:mod:`texvocab.capture.fold_regions`): the pose-dependent appearance a texture
vocabulary is meant to explain. ``texvocab eval`` reports PSNR and SSIM on those pixels
beside the whole-image numbers.

SSIM on a region: the SSIM map of the whole image (11-tap Gaussian windows, as
:func:`texvocab.metrics.image.ssim`) averaged over the region's pixels whose window lies
inside the image.

Where the render is empty the fold error is the truth itself, whatever the texture says:
``psnr_fold_drawn`` scores the region's pixels the render covers (opacity > 0.5; each
run its own pixels) and ``fold_empty`` is the share of the region it leaves empty, so a
strategy's effect on the folds it draws is read apart from the field's outline.
"""

from __future__ import annotations

import math

import numpy as np

from texvocab.metrics.image import (
    SSIM_K1,
    SSIM_K2,
    SSIM_RADIUS,
    _filter_valid,
    _gaussian_taps,
    _image_pair,
    psnr,
)

#: Fewest region pixels for which the metrics are reported (else None).
FOLD_MIN_PIXELS = 16
#: Opacity above which a pixel counts as drawn (the silhouette IoU's threshold).
DRAWN_OPACITY = 0.5


def ssim_map(pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """(H - 10, W - 10) SSIM per pixel (mean over channels) of images (H, W, 3), for the
    pixels whose window lies inside the image (offset :data:`SSIM_RADIUS`)."""
    p, g = _image_pair(pred, gt)
    taps = _gaussian_taps()
    ux, uy = _filter_valid(p, taps), _filter_valid(g, taps)
    vx = _filter_valid(p * p, taps) - ux * ux
    vy = _filter_valid(g * g, taps) - uy * uy
    vxy = _filter_valid(p * g, taps) - ux * uy
    c1, c2 = SSIM_K1**2, SSIM_K2**2
    s = ((2 * ux * uy + c1) * (2 * vxy + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2))
    return s.mean(axis=-1)


def fold_region_metrics(
    pred: np.ndarray, gt: np.ndarray, region: np.ndarray, alpha: np.ndarray | None = None
) -> dict[str, float | None] | None:
    """``{"psnr_fold", "ssim_fold", "fold_pixels"}`` of ``pred`` against ``gt`` (H, W, 3)
    on the bool ``region`` (H, W); with the render's opacity ``alpha`` (H, W) also
    ``psnr_fold_drawn`` (on the region's pixels with opacity > 0.5; None for fewer than
    :data:`FOLD_MIN_PIXELS`) and ``fold_empty`` (the share of the region at or below it).
    None when the region holds fewer than :data:`FOLD_MIN_PIXELS` pixels (inside the
    SSIM windows' reach) or was stored at another image size (a capture read
    downscaled)."""
    region = np.asarray(region, bool)
    if region.shape != np.shape(gt)[:2]:
        return None
    r = SSIM_RADIUS
    inner = region[r:-r, r:-r]
    if inner.sum() < FOLD_MIN_PIXELS:
        return None
    out: dict[str, float | None] = {
        "psnr_fold": psnr(pred, gt, mask=region),
        "ssim_fold": float(ssim_map(pred, gt)[inner].mean()),
        "fold_pixels": float(region.sum()),
    }
    if alpha is not None:
        drawn = region & (np.asarray(alpha).reshape(region.shape) > DRAWN_OPACITY)
        out["psnr_fold_drawn"] = psnr(pred, gt, mask=drawn) if drawn.sum() >= FOLD_MIN_PIXELS else None
        out["fold_empty"] = float(1.0 - drawn.sum() / region.sum())
    return out


def summarise_fold(per: list[dict[str, float] | None]) -> dict[str, float | int | None]:
    """Set summary: mean and standard error of ``psnr_fold`` / ``ssim_fold`` (and, where
    measured, ``psnr_fold_drawn`` / ``fold_empty``) over the images that have a fold
    region (and a value), and ``fold_images`` (how many)."""
    kept = [m for m in per if m is not None]
    out: dict[str, float | int | None] = {"fold_images": len(kept)}
    for k in ("psnr_fold", "ssim_fold", "psnr_fold_drawn", "fold_empty"):
        if k not in ("psnr_fold", "ssim_fold") and not any(k in m for m in kept):
            continue
        vals = np.asarray([m[k] for m in kept if m.get(k) is not None], np.float64)
        out[k] = float(vals.mean()) if len(vals) else None
        out[f"{k}_sem"] = float(vals.std(ddof=1) / math.sqrt(len(vals))) if len(vals) > 1 else None
    return out
