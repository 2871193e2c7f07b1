"""Texels a frame's views did not see (Sec. 3.2 with one camera): how they are filled.

A texture map U_t holds colour only where a training view of frame t saw the surface
(coverage > 0). With several cameras that is nearly all of the body; with one camera it is
the side facing it, about a third of the texels. Texels it did not see must not pass for
seen ones, or a key frame facing away hands the field the colours of the wrong side.

``data.unseen_texels`` chooses what an unseen texel holds:

* ``nearest``: the colour of the nearest seen texel of the same map in UV space (what every
  map stores on disk, so the encoder sees no black seams);
* ``mean``: the coverage-weighted mean of that texel over every training frame that saw it
  (the subject's average appearance there), and the nearest-seen colour of that mean where
  no training frame saw the texel. Held-out frames never enter the mean.
"""

from __future__ import annotations

import numpy as np
import torch
from scipy import ndimage

UNSEEN_TEXELS = ("nearest", "mean")


def mean_texture(textures: torch.Tensor, coverage: torch.Tensor) -> torch.Tensor:
    """The coverage-weighted mean texture of a capture's training frames.

    Args:
        textures: (T, 3, S, S) texture maps in [0, 1].
        coverage: (T, S, S) views that saw each texel (0: unseen).

    Returns:
        (3, S, S): Σ_t c_t U_t / Σ_t c_t where some frame saw the texel; elsewhere the value
        of the nearest such texel (the plain mean of the maps when none was seen at all).
    """
    w = coverage.to(textures.dtype)
    total = w.sum(0)
    mean = (textures * w[:, None]).sum(0) / total.clamp(min=1e-12)
    seen = (total > 0).numpy()
    if not seen.any():
        return textures.mean(0)
    if not seen.all():
        _, (iy, ix) = ndimage.distance_transform_edt(~seen, return_indices=True)
        mean = mean[:, torch.from_numpy(iy), torch.from_numpy(ix)]
    return mean


def fill_unseen_texels(textures: torch.Tensor, coverage: torch.Tensor, how: str) -> torch.Tensor:
    """The training texture maps with their unseen texels filled as ``how`` says
    (:data:`UNSEEN_TEXELS`): (T, 3, S, S) in, (T, 3, S, S) out; ``nearest`` returns them as
    they are."""
    if how not in UNSEEN_TEXELS:
        raise ValueError(f"unseen_texels must be one of {', '.join(UNSEEN_TEXELS)}; got {how!r}")
    if how == "nearest":
        return textures
    mean = mean_texture(textures, coverage)
    return torch.where((coverage > 0)[:, None], textures, mean[None])


def seen_share(coverage: torch.Tensor) -> np.ndarray:
    """(T,) the share of each frame's texels that some view saw, over the texels any frame saw."""
    any_seen = coverage.sum(0) > 0
    n = max(int(any_seen.sum()), 1)
    return ((coverage > 0) & any_seen).flatten(1).sum(1).numpy() / n
