"""A small compiled CPU triangle rasteriser (numba): per pixel, the nearest triangle,
its barycentrics and depth. Used for back-projection with a depth test (Eq. 2), for
silhouettes, and for the posed body's depth that bounds the ray marcher's shell.

Pixel centres sit at integer coordinates (OpenCV convention).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from texvocab.geometry._raster_jit import raster_triangles


@dataclass
class Raster:
    """Per-pixel result, (H, W) each; ``face`` is -1 where no triangle covers the pixel."""

    face: torch.Tensor  # (H, W) int64
    bary: torch.Tensor  # (H, W, 3)
    depth: torch.Tensor  # (H, W), +inf where empty

    @property
    def mask(self) -> torch.Tensor:
        return self.face >= 0


def rasterize(pix: torch.Tensor, depth: torch.Tensor, faces: torch.Tensor, width: int, height: int) -> Raster:
    """Rasterise projected triangles with a z-buffer (compiled:
    :func:`texvocab.geometry._raster_jit.raster_triangles`).

    Args:
        pix: (V, 2) projected vertex positions in pixels (x, y).
        depth: (V,) camera-space depth of each vertex (> 0 in front of the camera).
        faces: (F, 3) vertex indices.
        width, height: image size.

    Returns:
        :class:`Raster`. Triangles with any vertex behind the camera (depth <= 1e-6) are
        skipped; barycentrics are screen-space (perspective-correct depth is interpolated
        as 1/z); where two triangles meet a pixel at the same depth the later one wins.
    """
    face = np.full(height * width, -1, dtype=np.int64)
    bary = np.zeros((height * width, 3))
    best = np.full(height * width, np.inf)
    raster_triangles(
        np.ascontiguousarray(torch.as_tensor(pix).double().numpy()),
        np.ascontiguousarray(torch.as_tensor(depth).double().numpy()),
        np.ascontiguousarray(torch.as_tensor(faces).long().numpy()),
        int(width),
        int(height),
        face,
        bary,
        best,
    )
    return Raster(
        torch.from_numpy(face).view(height, width),
        torch.from_numpy(bary).float().view(height, width, 3),
        torch.from_numpy(best).float().view(height, width),
    )


def rasterize_mesh(vertices: torch.Tensor, faces: torch.Tensor, camera) -> Raster:
    """Rasterise a world-space mesh (V, 3) seen by a :class:`~texvocab.capture.Camera`."""
    pix, z = camera.project(vertices.detach().cpu().numpy())
    return rasterize(torch.as_tensor(pix), torch.as_tensor(z), faces, camera.width, camera.height)
