"""Reference marcher: slow and obviously correct, for tests and benchmarks.

Every pixel's ray is clipped to an axis-aligned box around the body; ``coarse``
uniform (stratified) samples, then ``fine`` importance samples from the coarse weights;
no shell, no early termination. Compositing is written out independently of
:func:`texvocab.render.volume.samples.composite` (a product of (1 - alpha) instead of an
exponential of summed optical depth), so the two can be compared.
"""

from __future__ import annotations

import time

import numpy as np
import torch

from texvocab.render.results import RenderResult, RenderStats
from texvocab.render.volume.field import Field, evaluate_field
from texvocab.render.volume.samples import midpoint_intervals, sample_pdf, stratified_positions


def mesh_bbox(vertices, margin: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """(min (3,), max (3,)) of vertices (V, 3), grown by ``margin`` metres."""
    v = np.asarray(torch.as_tensor(vertices).detach().cpu(), dtype=np.float64)
    return v.min(0) - margin, v.max(0) + margin


def ray_box(
    origins: torch.Tensor, dirs: torch.Tensor, lo, hi
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Slab test of rays (R, 3) against the box [lo, hi]: hit (R,), near (R,) >= 0, far."""
    lo, hi = (torch.as_tensor(np.asarray(b), dtype=torch.float64) for b in (lo, hi))
    o, d = origins.double(), dirs.double()
    d = torch.where(d.abs() < 1e-12, torch.full_like(d, 1e-12), d)
    a, b = (lo - o) / d, (hi - o) / d
    near = torch.minimum(a, b).amax(1).clamp(min=0)
    far = torch.maximum(a, b).amin(1)
    hit = far > near
    return hit, torch.where(hit, near, 0).float(), torch.where(hit, far, 0).float()


def composite_reference(
    sigma: torch.Tensor, rgb: torch.Tensor, deltas: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Weights (R, S), opacity (R,), colour (R, 3): alpha_i = 1 - exp(-sigma_i delta_i),
    T_i = prod_{j<i} (1 - alpha_j), w_i = T_i alpha_i."""
    alpha = 1 - torch.exp(-sigma * deltas)
    keep = torch.cumprod(1 - alpha, 1)
    trans = torch.cat([torch.ones_like(keep[:, :1]), keep[:, :-1]], 1)
    weights = trans * alpha
    return weights, weights.sum(1), (weights[..., None] * rgb).sum(1)


def _render_uniform_rays(
    field: Field,
    o: torch.Tensor,
    d: torch.Tensor,
    near: torch.Tensor,
    far: torch.Tensor,
    coarse: int,
    fine: int,
    chunk: int,
    generator: torch.Generator | None,
):
    """(rgb (R, 3) without background, opacity (R,), depth (R,), evals) for rays (R, 3)."""
    length = far - near
    u_c, edges = stratified_positions(length, None, coarse, generator)
    sigma, rgb = evaluate_field(
        field,
        (o[:, None] + (near[:, None] + u_c)[..., None] * d[:, None]).reshape(-1, 3),
        d.repeat_interleave(coarse, 0),
        chunk,
    )
    sigma, rgb = sigma.view(-1, coarse), rgb.view(-1, coarse, 3)
    weights, _, _ = composite_reference(sigma, rgb, edges[:, 1:] - edges[:, :-1])
    u_f = sample_pdf(edges, weights, fine, generator)
    sigma_f, rgb_f = evaluate_field(
        field,
        (o[:, None] + (near[:, None] + u_f)[..., None] * d[:, None]).reshape(-1, 3),
        d.repeat_interleave(fine, 0),
        chunk,
    )
    u, order = torch.cat([u_c, u_f], 1).sort(1)
    sigma = torch.cat([sigma, sigma_f.view(-1, fine)], 1).gather(1, order)
    rgb = torch.cat([rgb, rgb_f.view(-1, fine, 3)], 1).gather(1, order[..., None].expand(-1, -1, 3))
    starts, ends = midpoint_intervals(u, length)
    weights, acc, color = composite_reference(sigma, rgb, ends - starts)
    depth = (weights * (near[:, None] + u)).sum(1) / acc.clamp(min=1e-6)
    return color, acc, depth, len(o) * (coarse + fine)


def render_image_uniform(
    field: Field,
    camera,
    bbox_min,
    bbox_max,
    coarse: int = 64,
    fine: int = 64,
    background=(0.0, 0.0, 0.0),
    chunk_rays: int = 2048,
    chunk_points: int = 1 << 18,
    generator: torch.Generator | None = None,
) -> RenderResult:
    """Render every pixel of ``camera`` with ``coarse`` + ``fine`` samples per ray inside
    the box [bbox_min, bbox_max] (see :func:`mesh_bbox`); rays missing the box get the
    background. Same outputs as :func:`texvocab.render.render_image`."""
    start = time.perf_counter()
    H, W = camera.height, camera.width
    origins, dirs = camera.pixel_rays()
    hit, near, far = ray_box(origins, dirs, bbox_min, bbox_max)
    pix = torch.nonzero(hit).squeeze(1)
    bg = torch.as_tensor(background, dtype=torch.float32)
    rgb, alpha, depth = bg.repeat(H * W, 1), torch.zeros(H * W), torch.zeros(H * W)
    evals = 0
    for c in range(0, len(pix), chunk_rays):
        p = pix[c : c + chunk_rays]
        color, acc, dep, n = _render_uniform_rays(
            field, origins[p], dirs[p], near[p], far[p], coarse, fine, chunk_points, generator
        )
        rgb = rgb.index_put((p,), color + (1 - acc)[:, None] * bg)
        alpha, depth = alpha.index_put((p,), acc), depth.index_put((p,), dep)
        evals += n
    stats = RenderStats(evals, len(pix), H * W, time.perf_counter() - start)
    return RenderResult(rgb.view(H, W, 3), alpha.view(H, W), depth.view(H, W), stats)
