"""UV space: the one place where UV coordinates meet texture-image pixels, and the texel
map that inverts the UV parameterisation A of Sec. 3.2 (each texel's face and barycentrics).

``vt`` is in [0, 1]² with the origin at the bottom-left (OBJ); a texture image's row 0 is
the top (v = 1). Texel centres sit at ``(i + 0.5) / size``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np
import torch
from scipy import ndimage

from texvocab.geometry.raster import rasterize


def uv_to_pixel(uv: torch.Tensor, width: int, height: int) -> torch.Tensor:
    """(..., 2) UV -> (..., 2) continuous pixel coordinates (x, y), texel centres integral."""
    x = uv[..., 0] * width - 0.5
    y = (1.0 - uv[..., 1]) * height - 0.5
    return torch.stack([x, y], -1)


def pixel_to_uv(pix: torch.Tensor, width: int, height: int) -> torch.Tensor:
    """Inverse of :func:`uv_to_pixel`."""
    u = (pix[..., 0] + 0.5) / width
    v = 1.0 - (pix[..., 1] + 0.5) / height
    return torch.stack([u, v], -1)


def uv_to_grid(uv: torch.Tensor) -> torch.Tensor:
    """UV -> ``torch.nn.functional.grid_sample`` coordinates in [-1, 1] (align_corners=False)."""
    return torch.stack([uv[..., 0] * 2 - 1, 1 - uv[..., 1] * 2], -1)


@dataclass
class TexelMap:
    """Per covered texel (N of them): ``face`` (N,), ``bary`` (N, 3); ``covered`` (S, S)
    marks texels inside some UV triangle; ``nearest`` (2, S, S) gives, for every texel,
    the (row, col) of the nearest covered texel (to fill gaps without seams)."""

    size: int
    covered: np.ndarray
    face: np.ndarray
    bary: np.ndarray
    nearest: tuple[np.ndarray, np.ndarray]

    def points(self, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
        """(N, 3) surface points of the covered texels for vertex positions (V, 3)."""
        return np.einsum("nk,nkc->nc", self.bary, vertices[faces[self.face]])

    def interpolate(self, values: np.ndarray, faces: np.ndarray) -> np.ndarray:
        """(N, C) per-texel barycentric interpolation of per-vertex values (V, C)."""
        return np.einsum("nk,nkc->nc", self.bary, values[faces[self.face]])

    @cached_property
    def source(self) -> np.ndarray:
        """(S·S,) for every texel (row-major) the index among the N covered texels of the
        nearest covered one (itself when covered): ``to_image``'s fill as one gather."""
        index = np.full(self.covered.shape, -1, np.int64)
        index[self.covered] = np.arange(int(self.covered.sum()))
        return index[self.nearest].reshape(-1)

    def to_image(self, values: np.ndarray, fill: bool = True) -> np.ndarray:
        """Scatter (N, ...) texel values into an (S, S, ...) image; uncovered texels copy
        their nearest covered texel when ``fill``, else stay zero."""
        values = np.asarray(values)
        if fill and len(values):
            return values[self.source].reshape((self.size, self.size) + values.shape[1:])
        img = np.zeros((self.size, self.size) + values.shape[1:], dtype=values.dtype)
        img[self.covered] = values
        return img[self.nearest] if fill else img


@lru_cache(maxsize=8)
def _texel_map(vt_bytes: bytes, ft_bytes: bytes, n_vt: int, size: int) -> TexelMap:
    vt = torch.as_tensor(np.frombuffer(vt_bytes, dtype=np.float64).reshape(n_vt, 2).copy())
    ft = torch.as_tensor(np.frombuffer(ft_bytes, dtype=np.int64).reshape(-1, 3).copy())
    pix = uv_to_pixel(vt, size, size)
    r = rasterize(pix, torch.ones(len(pix), dtype=torch.float64), ft, size, size)
    face = r.face.numpy()
    covered = face >= 0
    _, nearest = ndimage.distance_transform_edt(~covered, return_indices=True)
    return TexelMap(size, covered, face[covered], r.bary.double().numpy()[covered], (nearest[0], nearest[1]))


def texel_map(body, size: int) -> TexelMap:
    """The (cached) :class:`TexelMap` of ``body``'s UV layout at ``size`` × ``size``."""
    if body.vt is None or body.ft is None:
        raise ValueError(
            f"{body.name} has no UV layout (vt/ft); give an SMPL UV file "
            "(smpl_uv.obj next to the model) or use the default body"
        )
    vt = np.ascontiguousarray(body.vt.double().numpy())
    ft = np.ascontiguousarray(body.ft.numpy().astype(np.int64))
    return _texel_map(vt.tobytes(), ft.tobytes(), len(vt), int(size))
