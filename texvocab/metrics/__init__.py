"""Image metrics for rendered avatars against ground truth (paper Sec. 4.1: PSNR, SSIM,
LPIPS, FID; plus KID).

- :mod:`texvocab.metrics.image`: PSNR, SSIM, the mask-bbox / full-frame protocols,
  :func:`evaluate_pair`;
- :mod:`texvocab.metrics.perceptual`: LPIPS-VGG as a metric and a frozen loss;
- :mod:`texvocab.metrics.frechet`: FID (from :data:`FID_MIN_IMAGES` images per set) and
  KID (unbiased polynomial-kernel MMD², any set of 2 or more) from one pass of Inception
  pool features, the Fréchet distance.

LPIPS, FID and KID need pretrained files that are never downloaded; without them they
return ``None`` and say once on the ``texvocab`` logger what is missing.
"""

from texvocab.metrics.frechet import (
    FID_MIN_IMAGES,
    fid,
    fid_available,
    frechet_distance,
    frechet_distance_from_features,
    inception_extractor,
    inception_features,
    inception_scores,
    kid,
    kid_from_features,
    mmd2_unbiased,
    polynomial_kernel,
    scores_from_features,
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
    "FID_MIN_IMAGES",
    "LPIPS",
    "PSNR_MAX_DB",
    "evaluate_pair",
    "fid",
    "fid_available",
    "frechet_distance",
    "frechet_distance_from_features",
    "inception_extractor",
    "inception_features",
    "inception_scores",
    "kid",
    "kid_from_features",
    "lpips",
    "lpips_available",
    "mask_bbox",
    "metrics_full_frame",
    "metrics_in_bbox",
    "mmd2_unbiased",
    "polynomial_kernel",
    "psnr",
    "scores_from_features",
    "ssim",
]
