"""Image metrics for rendered avatars against ground truth (paper Sec. 4.1: PSNR, SSIM,
LPIPS, FID).

- :mod:`texvocab.metrics.image`: PSNR, SSIM, the mask-bbox / full-frame protocols,
  :func:`evaluate_pair`;
- :mod:`texvocab.metrics.perceptual`: LPIPS-VGG as a metric and a frozen loss;
- :mod:`texvocab.metrics.frechet`: FID and the Fréchet distance.

LPIPS and FID need pretrained files that are never downloaded; without them they
return ``None`` and say once on the ``texvocab`` logger what is missing.
"""
from texvocab.metrics.frechet import (
    fid,
    fid_available,
    frechet_distance,
    frechet_distance_from_features,
    inception_features,
)
from texvocab.metrics.image import (
    PSNR_MAX_DB,
    evaluate_pair,
    mask_bbox,
    metrics_full_frame,
    metrics_in_bbox,
    psnr,
    ssim,
)
from texvocab.metrics.perceptual import LPIPS, lpips, lpips_available

__all__ = [
    "LPIPS", "PSNR_MAX_DB", "evaluate_pair", "fid", "fid_available", "frechet_distance",
    "frechet_distance_from_features", "inception_features", "lpips", "lpips_available",
    "mask_bbox", "metrics_full_frame", "metrics_in_bbox", "psnr", "ssim",
]
