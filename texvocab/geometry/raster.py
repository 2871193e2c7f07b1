"""A small vectorised CPU triangle rasteriser (torch): per pixel, the nearest triangle,
its barycentrics and depth. Used for back-projection with a depth test (Eq. 2), for
silhouettes, and for the posed body's depth that bounds the ray marcher's shell.

Pixel centres sit at integer coordinates (OpenCV convention).
"""
from __future__ import annotations

from dataclasses import dataclass

import torch


@dataclass
class Raster:
    """Per-pixel result, (H, W) each; ``face`` is -1 where no triangle covers the pixel."""

    face: torch.Tensor  # (H, W) int64
    bary: torch.Tensor  # (H, W, 3)
    depth: torch.Tensor  # (H, W), +inf where empty

    @property
    def mask(self) -> torch.Tensor:
        return self.face >= 0


def _candidate_pixels(tri: torch.Tensor, width: int, height: int, chunk_pixels: int):
    """Yield (face ids, px, py) for every pixel inside each triangle's bounding box,
    in chunks of about ``chunk_pixels`` pairs."""
    lo = torch.ceil(tri.amin(1)).long()
    hi = torch.floor(tri.amax(1)).long()
    lo[:, 0].clamp_(0, width - 1)
    lo[:, 1].clamp_(0, height - 1)
    hi[:, 0].clamp_(max=width - 1)
    hi[:, 1].clamp_(max=height - 1)
    bw, bh = (hi - lo + 1).clamp(min=0).unbind(1)
    counts = bw * bh
    valid = torch.nonzero(counts > 0).squeeze(1)
    if valid.numel() == 0:
        return
    cum = torch.cumsum(counts[valid], 0)
    start = 0
    while start < len(valid):
        base = int(cum[start - 1]) if start else 0
        stop = int(torch.searchsorted(cum, base + chunk_pixels, right=True))
        stop = max(stop, start + 1)
        faces = valid[start:stop]
        n = counts[faces]
        fid = torch.repeat_interleave(faces, n)
        first = torch.repeat_interleave(torch.cumsum(n, 0) - n, n)
        k = torch.arange(len(fid)) - first
        px = lo[fid, 0] + k % bw[fid]
        py = lo[fid, 1] + k // bw[fid]
        yield fid, px, py
        start = stop


def rasterize(pix: torch.Tensor, depth: torch.Tensor, faces: torch.Tensor, width: int,
              height: int, chunk_pixels: int = 4_000_000) -> Raster:
    """Rasterise projected triangles with a z-buffer.

    Args:
        pix: (V, 2) projected vertex positions in pixels (x, y).
        depth: (V,) camera-space depth of each vertex (> 0 in front of the camera).
        faces: (F, 3) vertex indices.
        width, height: image size.

    Returns:
        :class:`Raster`. Triangles with any vertex behind the camera (depth <= 1e-6) are
        skipped; barycentrics are screen-space (perspective-correct depth is interpolated
        as 1/z).
    """
    pix = pix.double()
    faces = faces.long()
    front = (depth[faces] > 1e-6).all(1)
    face_ids = torch.nonzero(front).squeeze(1)
    tri = pix[faces[face_ids]]  # (F', 3, 2)
    inv_z = 1.0 / depth.double()[faces[face_ids]]  # (F', 3)
    best = torch.full((height * width,), float("inf"), dtype=torch.float64)
    hits = []
    for local, px, py in _candidate_pixels(tri, width, height, chunk_pixels):
        t = tri[local]
        a, b, c = t[:, 0], t[:, 1], t[:, 2]
        area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
        x, y = px.double(), py.double()
        w0 = (b[:, 0] - x) * (c[:, 1] - y) - (b[:, 1] - y) * (c[:, 0] - x)
        w1 = (c[:, 0] - x) * (a[:, 1] - y) - (c[:, 1] - y) * (a[:, 0] - x)
        w2 = area - w0 - w1
        ok = area.abs() > 1e-12
        bary = torch.stack([w0, w1, w2], 1) / torch.where(ok, area, torch.ones_like(area))[:, None]
        inside = ok & (bary >= -1e-9).all(1)
        if not inside.any():
            continue
        local, px, py, bary = local[inside], px[inside], py[inside], bary[inside]
        z = 1.0 / (bary * inv_z[local]).sum(1)
        idx = py * width + px
        best.scatter_reduce_(0, idx, z, reduce="amin")
        hits.append((local, idx, bary, z))
    face = torch.full((height * width,), -1, dtype=torch.long)
    out_bary = torch.zeros(height * width, 3, dtype=torch.float64)
    for local, idx, bary, z in hits:
        win = z <= best[idx]
        face[idx[win]] = face_ids[local[win]]
        out_bary[idx[win]] = bary[win]
    return Raster(face.view(height, width), out_bary.view(height, width, 3).float(),
                  best.view(height, width).float())


def rasterize_mesh(vertices: torch.Tensor, faces: torch.Tensor, camera) -> Raster:
    """Rasterise a world-space mesh (V, 3) seen by a :class:`~texvocab.capture.Camera`."""
    pix, z = camera.project(vertices.detach().cpu().numpy())
    return rasterize(torch.as_tensor(pix), torch.as_tensor(z), faces, camera.width, camera.height)
