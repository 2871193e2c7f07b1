"""Pixel metrics (PSNR, SSIM) and the evaluation protocols avatar papers report.

Images are float RGB ``(H, W, 3)`` in [0, 1] (numpy arrays or torch tensors, any float
dtype); all arithmetic is float64 numpy and every metric returns a Python float.
Protocols differ between papers and change the numbers; each function says which one
it follows:

- full frame (TAVA; Animatable Gaussians after setting the GT background): PSNR and
  SSIM over the whole image, :func:`metrics_full_frame`;
- mask bounding box (AniNeRF style): the crop of the bounding box of a mask,
  :func:`metrics_in_bbox`. AniNeRF itself averages PSNR over the pixels of its
  ``mask_at_box`` (the projected 3D SMPL box) rather than the rectangle: that number
  is ``psnr(pred, gt, mask=mask_at_box)``; and its SSIM is scikit-image's *default*
  (7x7 uniform window, sample covariance), not the Gaussian SSIM used here.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from texvocab.metrics.perceptual import LPIPS, lpips, lpips_with

PSNR_MAX_DB = 100.0  # PSNR of identical images (mse 0) and cap for any mse <= 1e-10
SSIM_SIGMA = 1.5
SSIM_RADIUS = 5  # int(3.5 * sigma + 0.5): scikit-image's truncate=3.5 -> 11 taps
SSIM_WINDOW = 2 * SSIM_RADIUS + 1  # the smallest image (and bounding box) SSIM measures
SSIM_K1, SSIM_K2 = 0.01, 0.03

ArrayLike = np.ndarray | torch.Tensor


def _as_array(x: ArrayLike) -> np.ndarray:
    """float64 numpy copy of a numpy array or (possibly grad-carrying) torch tensor."""
    if isinstance(x, torch.Tensor):
        x = x.detach().cpu().numpy()
    return np.asarray(x, dtype=np.float64)


def _image_pair(pred: ArrayLike, gt: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """``pred``, ``gt`` as float64 ``(H, W, C)``; shapes must agree."""
    p, g = _as_array(pred), _as_array(gt)
    if p.shape != g.shape:
        raise ValueError(f"pred and gt must have the same shape, got {p.shape} and {g.shape}")
    if p.ndim == 2:
        p, g = p[..., None], g[..., None]
    if p.ndim != 3:
        raise ValueError(f"images must be (H, W, 3) or (H, W), got {p.shape}")
    return p, g


def _as_mask(mask: ArrayLike, shape: tuple[int, int]) -> np.ndarray:
    m = mask.detach().cpu().numpy() if isinstance(mask, torch.Tensor) else np.asarray(mask)
    if m.shape != shape:
        raise ValueError(f"mask must be (H, W) = {shape}, got {m.shape}")
    return m.astype(bool)


def psnr(pred: ArrayLike, gt: ArrayLike, mask: ArrayLike | None = None) -> float:
    """Peak signal-to-noise ratio in dB for images ``(H, W, 3)`` in [0, 1] (data range 1):
    ``10 log10(1 / mse)`` with the mse over all pixels and channels, or over the pixels
    where the boolean ``mask`` ``(H, W)`` is true. Capped at :data:`PSNR_MAX_DB` (100 dB),
    which identical images get; NaN when either image holds a NaN or inf."""
    p, g = _image_pair(pred, gt)
    sq = (p - g) ** 2
    if mask is not None:
        m = _as_mask(mask, p.shape[:2])
        if not m.any():
            raise ValueError("psnr: mask selects no pixels")
        sq = sq[m]
    mse = float(sq.mean())
    if not math.isfinite(mse):  # a NaN or inf image scores NaN, never the cap
        return math.nan
    return PSNR_MAX_DB if mse <= 1e-10 else min(PSNR_MAX_DB, -10.0 * math.log10(mse))


def _gaussian_taps(sigma: float = SSIM_SIGMA, radius: int = SSIM_RADIUS) -> np.ndarray:
    """Normalised 1-D Gaussian ``(2 radius + 1,)``, as ``scipy.ndimage.gaussian_filter``."""
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    taps = np.exp(-0.5 * x * x / (sigma * sigma))
    return taps / taps.sum()


def _filter_valid(x: np.ndarray, taps: np.ndarray) -> np.ndarray:
    """Separable correlation of ``(H, W, ...)`` with ``taps`` on rows and columns, only
    where the window fits: ``(H - k + 1, W - k + 1, ...)``."""
    k = len(taps)
    x = np.lib.stride_tricks.sliding_window_view(x, k, axis=0) @ taps
    return np.lib.stride_tricks.sliding_window_view(x, k, axis=1) @ taps


def ssim(pred: ArrayLike, gt: ArrayLike) -> float:
    """Mean structural similarity (Wang et al. 2004) of images ``(H, W, 3)`` (or
    ``(H, W)``) in [0, 1], per channel then averaged over channels; needs H, W >= 11.

    Convention: Gaussian window of 11 taps (sigma 1.5), population (co)variances,
    K1 = 0.01, K2 = 0.03, data range 1, and the mean taken over the pixels at least 5
    from the border, i.e. scikit-image's ``structural_similarity(pred, gt,
    gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=1,
    channel_axis=-1)`` computed in float64 (checked against scikit-image 0.26.0 in
    tests/metrics/test_metrics.py). Only windows that lie inside the image enter the mean, so
    the border handling of the filter does not matter. scikit-image's *defaults*
    (7x7 uniform window, sample covariance) and its float32 path give other numbers,
    and they have changed between versions (0.19 vs 0.23): quote this convention.
    """
    p, g = _image_pair(pred, gt)
    h, w = p.shape[:2]
    if min(h, w) < 2 * SSIM_RADIUS + 1:
        raise ValueError(f"ssim needs images of at least 11x11 pixels, got {h}x{w}")
    taps = _gaussian_taps()
    ux, uy = _filter_valid(p, taps), _filter_valid(g, taps)
    vx = _filter_valid(p * p, taps) - ux * ux
    vy = _filter_valid(g * g, taps) - uy * uy
    vxy = _filter_valid(p * g, taps) - ux * uy
    c1, c2 = SSIM_K1**2, SSIM_K2**2
    s = ((2 * ux * uy + c1) * (2 * vxy + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2))
    return float(s.mean(axis=(0, 1)).mean())


def mask_bbox(mask: ArrayLike, margin: int = 0, min_size: int = 0) -> tuple[int, int, int, int]:
    """Bounding box ``(y0, y1, x0, x1)`` (half-open: rows y0..y1-1) of the true pixels of
    a boolean mask ``(H, W)``, grown by ``margin`` pixels on each side, then widened about
    its centre to at least ``min_size`` pixels per side (SSIM's 11-pixel window on a thin
    figure), and clipped to the image. Raises ``ValueError`` for an empty mask."""
    m = mask.detach().cpu().numpy() if isinstance(mask, torch.Tensor) else np.asarray(mask)
    if m.ndim != 2:
        raise ValueError(f"mask must be (H, W), got {m.shape}")
    m = m.astype(bool)
    rows, cols = np.flatnonzero(m.any(axis=1)), np.flatnonzero(m.any(axis=0))
    if rows.size == 0:
        raise ValueError("mask is empty: it has no bounding box")
    h, w = m.shape
    box = []
    for lo, hi, n in (
        (int(rows[0]) - margin, int(rows[-1]) + 1 + margin, h),
        (int(cols[0]) - margin, int(cols[-1]) + 1 + margin, w),
    ):
        short = max(0, min(min_size, n) - (hi - lo))
        lo, hi = lo - short // 2, hi + short - short // 2
        shift = max(0, -lo) - max(0, hi - n)  # slide back inside the image
        box += [max(0, lo + shift), min(n, hi + shift)]
    return box[0], box[1], box[2], box[3]


def crop_to_bbox(image: ArrayLike, bbox: tuple[int, int, int, int]) -> ArrayLike:
    """``image[y0:y1, x0:x1]`` for ``bbox = (y0, y1, x0, x1)`` (numpy or torch)."""
    y0, y1, x0, x1 = bbox
    return image[y0:y1, x0:x1]


def metrics_in_bbox(pred: ArrayLike, gt: ArrayLike, mask: ArrayLike, margin: int = 0) -> dict[str, float]:
    """``{"psnr", "ssim"}`` on the crop of the bounding box of ``mask`` ``(H, W)`` (plus
    ``margin`` pixels), AniNeRF style: every pixel of the rectangle counts, background
    included. Images ``(H, W, 3)`` in [0, 1]; the crop must be at least 11x11 for SSIM."""
    bbox = mask_bbox(mask, margin, SSIM_WINDOW)
    p, g = crop_to_bbox(pred, bbox), crop_to_bbox(gt, bbox)
    return {"psnr": psnr(p, g), "ssim": ssim(p, g)}


def metrics_full_frame(pred: ArrayLike, gt: ArrayLike) -> dict[str, float]:
    """``{"psnr", "ssim"}`` over the whole image (TAVA; Animatable Gaussians after the
    GT background outside the mask is set to the rendering's background colour)."""
    return {"psnr": psnr(pred, gt), "ssim": ssim(pred, gt)}


def evaluate_pair(
    pred: ArrayLike, gt: ArrayLike, mask: ArrayLike, lpips_model: LPIPS | None = None
) -> dict[str, float | None]:
    """All image metrics of one rendering ``pred`` against ``gt`` ((H, W, 3) in [0, 1])
    with the foreground ``mask`` (H, W):

    - ``psnr_bbox``, ``ssim_bbox``: :func:`metrics_in_bbox` (mask bounding box crop);
    - ``psnr_full``, ``ssim_full``: :func:`metrics_full_frame`;
    - ``lpips``: LPIPS (VGG, v0.1) on the same bounding-box crop, or ``None`` when its
      weights are absent (logged once). Pass a loaded
      :class:`~texvocab.metrics.perceptual.LPIPS` as ``lpips_model`` to choose the weights;
      otherwise the default search of :func:`texvocab.metrics.perceptual.lpips` applies.
      Papers print LPIPS x 1000 (TexVocab Table 1).
    """
    box = metrics_in_bbox(pred, gt, mask)
    full = metrics_full_frame(pred, gt)
    bbox = mask_bbox(mask, 0, SSIM_WINDOW)
    p, g = crop_to_bbox(pred, bbox), crop_to_bbox(gt, bbox)
    perceptual = lpips(p, g) if lpips_model is None else lpips_with(lpips_model, p, g)
    return {
        "psnr_bbox": box["psnr"],
        "ssim_bbox": box["ssim"],
        "psnr_full": full["psnr"],
        "ssim_full": full["ssim"],
        "lpips": perceptual,
    }
