"""The surface plan of one camera and posed mesh: the mesh's rasterisation tells each pixel's
ray where its surface is (the avatar's SDF is the posed body's signed distance plus a
residual, and its density is zero beyond the shell, δ from the mesh, so a ray's first
surface lies within δ of the mesh's first hit), at which cosine it meets it, and which rays
pass a surface nearer than their own (silhouette fringes, occlusion edges) and where they
come closest to it. The guided marcher triages its rays by the plan
(:mod:`texvocab.render.guided.triage`), and training draws its band rays from it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from scipy import ndimage

from texvocab.geometry.raster import rasterize_mesh

_FAR = 1e6  # stands for "no surface" in the min/max filters (metres)


@dataclass
class SurfacePlan:
    """Per pixel (row-major, H·W) of one camera and posed mesh: ``t_hit`` ray distance of
    the mesh's first hit (inf: none), ``cos`` |cosine| between the ray and the hit face's
    normal (0: none), ``passby`` the ray passes a surface nearer than its own hit (more
    than δ nearer, within ``radius`` pixels) or misses the mesh near one; ``t_pass``,
    ``t_behind`` where a passing ray comes closest to the surface it passes (two probe
    distances; inf for other rays); ``band`` the band rays: hit, cos >= min_cos, no
    passby; ``face`` the hit face (long; -1: none)."""

    t_hit: torch.Tensor
    cos: torch.Tensor
    passby: torch.Tensor
    t_pass: torch.Tensor
    t_behind: torch.Tensor
    band: torch.Tensor
    face: torch.Tensor

    @property
    def hit(self) -> torch.Tensor:
        return torch.isfinite(self.t_hit)


def _frontmost_neighbour(t_map: torch.Tensor, radius: int) -> torch.Tensor:
    """For each pixel of t_map (H, W) (ray distance of the mesh hit, inf where missed):
    the smallest hit distance within its (2 radius + 1)² window (_FAR where none), as a
    separable minimum filter (rows, then columns)."""
    k = 2 * radius + 1
    neg = -torch.where(torch.isfinite(t_map), t_map, _FAR)[None, None]
    neg = F.max_pool2d(F.max_pool2d(neg, (k, 1), 1, (radius, 0)), (1, k), 1, (0, radius))
    return -neg.reshape(-1)


def _frontmost_pixel(t_map: torch.Tensor, radius: int, pix: torch.Tensor) -> torch.Tensor:
    """The flat index of the frontmost hit pixel in the window of each pixel of ``pix``
    (n,) (flat indices into t_map (H, W))."""
    H, W = t_map.shape
    if len(pix) == 0:
        return pix.clone()
    d = torch.arange(-radius, radius + 1)
    y = (pix // W)[:, None, None] + d[None, :, None]
    x = (pix % W)[:, None, None] + d[None, None, :]
    inside = (y >= 0) & (y < H) & (x >= 0) & (x < W)
    flat = (y.clamp(0, H - 1) * W + x.clamp(0, W - 1)).reshape(len(pix), -1)
    t = torch.where(torch.isfinite(t_map), t_map, _FAR).reshape(-1)[flat]
    t = torch.where(inside.reshape(len(pix), -1), t, 2 * _FAR)
    return flat.gather(1, t.argmin(1, keepdim=True)).squeeze(1)


def plan_surface(
    vertices: torch.Tensor,
    faces: torch.Tensor,
    camera,
    dirs: torch.Tensor,
    shell_width: float,
    reach: float,
    min_cos: float,
) -> SurfacePlan:
    """The :class:`SurfacePlan` of a posed mesh (V, 3), (F, 3) seen by ``camera`` with
    pixel ray directions dirs (H·W, 3). ``reach``: how far from a ray a passed surface can
    still show (metres; the renderer uses min(δ, miss_margin β), training δ)."""
    H, W = camera.height, camera.width
    raster = rasterize_mesh(vertices, faces, camera)
    along_z = dirs.double() @ torch.as_tensor(camera.R[2], dtype=torch.float64)
    t_hit = (raster.depth.view(-1).double() / along_z).float()
    hit = torch.isfinite(t_hit)
    cos = torch.zeros(H * W)
    none = torch.full((H * W,), torch.inf)
    if not hit.any():
        nothing = torch.zeros(H * W, dtype=torch.bool)
        return SurfacePlan(t_hit, cos, nothing, none, none.clone(), nothing, raster.face.view(-1))
    z_min = float(raster.depth.view(-1)[hit].min())
    radius = max(min(int(math.ceil(reach * float(camera.K[0, 0]) / max(z_min, 1e-6))), 64), 1)
    front = _frontmost_neighbour(t_hit.view(H, W), radius)
    tri = vertices.detach().float()[faces]
    normal = F.normalize(torch.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], dim=1), dim=1)
    cos[hit] = (normal[raster.face.view(-1)[hit]] * dirs[hit]).sum(1).abs()
    # rays that pass a surface nearer than their own (or miss the mesh): a neighbour hit
    # nearer by more than δ plus what the hit face's own slope explains
    c = cos.clamp(min=min_cos)
    slope = radius * t_hit / float(camera.K[0, 0]) * (1 - c * c).sqrt() / c
    own = torch.where(hit & (cos >= min_cos), t_hit - slope, t_hit)
    passby = (front < _FAR / 2) & (front < torch.where(hit, own, torch.inf) - shell_width)
    band = hit & (cos >= min_cos) & ~passby
    # A passing ray is probed where it comes closest to the surface it passes: a miss near
    # the nearest hit pixel's surface point, a hit behind an occlusion edge near the
    # nearest surface point of its window. The silhouette's tangent point lies up to a
    # pixel footprint per pixel of distance behind that point, where a second probe looks.
    gap, (iy, ix) = ndimage.distance_transform_edt(~hit.view(H, W).numpy(), return_indices=True)
    gap = torch.from_numpy(gap).float().view(-1)
    nearest = torch.from_numpy((iy * W + ix).reshape(-1)).long()
    gap = torch.where(hit, float(radius), gap)
    p_idx = torch.nonzero(passby).squeeze(1)
    behind = hit[p_idx]  # hits behind an occlusion edge: the window's frontmost hit
    nearest[p_idx[behind]] = _frontmost_pixel(t_hit.view(H, W), radius, p_idx[behind])
    q = nearest[p_idx]
    t_pass, t_behind = none, none.clone()
    t_pass[p_idx] = ((t_hit[q, None] * dirs[q]) * dirs[p_idx]).sum(1)
    t_behind[p_idx] = t_pass[p_idx] * (1 + gap[p_idx] / float(camera.K[0, 0]))
    return SurfacePlan(t_hit, cos, passby, t_pass, t_behind, band, raster.face.view(-1))
