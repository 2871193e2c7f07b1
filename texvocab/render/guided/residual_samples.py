"""The residual rays' mesh samples, ray by ray: the coarse passes that narrow each ray's
stretch of shell, the 4 ``residual_step`` β pass over what they keep, the part of the ray
that matters and its refinement (:mod:`texvocab.render.guided.residual`, steps 1-2), with
each ray's samples held as its own run of a flat array and the per-ray steps compiled
(:mod:`texvocab.render.kernels.residual_jit`). The same samples as the torch reference
:func:`~texvocab.render.guided.residual.padded_mesh_samples`, which pads every ray to the
longest (measured on a trained avatar: a third of a frame's residual-ray time went to
whole-array operations over that padding); only the rays no part of which matters (left
to the marcher either way) may be placed otherwise."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from texvocab.render.kernels.residual_jit import parts_that_matter, refine_counts, refine_fill

#: queries the mesh: points (n, 3) float64 -> signed distance (n,) (the cap beyond it), face (n,)
Query = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


class _Rays:
    """Rays (R,) from origin (3,) or origins (R, 3) along dirs (R, 3); their points are
    placed in float32, as the torch reference places them, and queried in float64."""

    def __init__(self, origin: torch.Tensor, dirs: torch.Tensor):
        self.origin = origin.detach().float().numpy()
        self.dirs = dirs.detach().float().numpy()

    def points(self, ray: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Points (n, 3) float64 at distances t (n,) float32 along rays ray (n,)."""
        o = self.origin if self.origin.ndim == 1 else self.origin[ray]
        return (o + t[:, None] * self.dirs[ray]).astype(np.float64)


def _sampled(rays: _Rays, near: np.ndarray, far: np.ndarray, step: float, query: Query):
    """d every ``step`` over [near, far] (R,) float32, the last sample at far (two at
    least): offsets (R + 1,), t, d (flat float32), f (flat)."""
    step32 = np.float32(step)
    with np.errstate(invalid="ignore"):  # a non-finite interval (a broken field) takes one
        span = np.ceil(np.maximum(far - near, np.float32(0)) / step32)  # step, as in torch
    last = np.where(np.isfinite(span), np.maximum(span, 1), 1).astype(np.int64)
    offsets = np.zeros(len(near) + 1, np.int64)
    np.cumsum(last + 1, out=offsets[1:])
    ray = np.repeat(np.arange(len(near)), last + 1)
    col = (np.arange(offsets[-1]) - offsets[ray]).astype(np.float32)
    t = np.minimum(near[ray] + col * step32, far[ray])
    d, f = query(rays.points(ray, t))
    return offsets, t, d.astype(np.float32), f


def _parts(offsets, t, d, r0, beta: float, cap: float, keep: float, opaque: float):
    """parts_that_matter on ŝ = d + r0 (the cap beyond it), float32: low (flat), first,
    end, found (R,)."""
    R = len(offsets) - 1
    cap32 = np.float32(cap)
    s = np.where(d < cap32, d + np.repeat(r0, np.diff(offsets)), cap32).astype(np.float32)
    low = np.zeros(len(t), np.bool_)
    first, end = np.empty(R, np.int64), np.empty(R, np.int64)
    found = np.empty(R, np.bool_)
    parts_that_matter(offsets, t, s, beta, keep, np.float32(opaque), low, first, end, found)
    return low, first, end, found


def ragged_mesh_samples(
    query: Query,
    origin: torch.Tensor,
    dirs: torch.Tensor,
    near: torch.Tensor,
    far: torch.Tensor,
    step: float,
    r0: torch.Tensor,
    beta: float,
    cap: float,
    levels: int,
    split: int,
    keep: float,
    opaque: float,
):
    """The residual rays' mesh samples: t, d (R, N) float (each ray's run first, then its
    last repeated), f (R, N) long, count (R,) and found (R,) bool, as
    :func:`~texvocab.render.guided.residual.padded_mesh_samples` returns them (its
    arguments; ``step`` the 4 ``residual_step`` β pass's, ``split`` the refinement's)."""
    rays = _Rays(origin, dirs)
    r0n = r0.detach().float().numpy().reshape(-1)
    lo, hi = near.detach().float().numpy(), far.detach().float().numpy()
    narrowed = np.ones(len(lo), np.bool_)
    for k in range(levels, 0, -1):
        offsets, t, d, _ = _sampled(rays, lo, hi, step * split**k, query)
        _, first, end, found = _parts(offsets, t, d, r0n, beta, cap, keep, opaque)
        narrowed &= found
        n_last = offsets[1:] - 1
        lo = t[offsets[:-1] + first]
        hi = np.where(narrowed, t[np.minimum(offsets[:-1] + end + 1, n_last)], lo)
    offsets, t, d, f = _sampled(rays, lo, hi, step, query)
    low, first, end, found = _parts(offsets, t, d, r0n, beta, cap, keep, opaque)
    count = refine_counts(first, end, low, offsets, split)
    new_offsets = np.zeros(len(count) + 1, np.int64)
    np.cumsum(count, out=new_offsets[1:])
    total = int(new_offsets[-1])
    t2, d2 = np.empty(total, np.float32), np.empty(total, np.float32)
    f2 = np.empty(total, np.int64)
    new = np.empty(total, np.bool_)
    refine_fill(first, end, low, offsets, t, d, f, split, new_offsets, t2, d2, f2, new)
    ray = np.repeat(np.arange(len(count)), count)
    at = np.flatnonzero(new)
    d_new, f2[at] = query(rays.points(ray[at], t2[at]))
    d2[at] = d_new
    # pack: row i holds its run, then its last sample repeated
    N = int(count.max())
    col = np.minimum(np.arange(N)[None, :], count[:, None] - 1)
    idx = new_offsets[:-1, None] + col
    dtype = dirs.dtype
    return (
        torch.from_numpy(t2[idx]).to(dtype),
        torch.from_numpy(d2[idx]).to(dtype),
        torch.from_numpy(f2[idx]),
        torch.from_numpy(count),
        torch.from_numpy(found & narrowed),
    )
