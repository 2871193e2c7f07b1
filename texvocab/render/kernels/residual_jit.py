"""Compiled per-ray loops of the residual rays' mesh samples
(:mod:`texvocab.render.guided.residual_samples`): each ray's samples are a run of a flat
array (ray i holds ``offsets[i]:offsets[i + 1]``), so no ray is padded to the longest, and
the steps that the torch reference (:func:`texvocab.render.guided.residual.padded_mesh_samples`)
does as a dozen whole-array operations run as one pass over each ray (numba; ``cache``
keeps the machine code in ``__pycache__``; IEEE division, ``error_model="numpy"``, so a
non-finite field gives NaN as torch does instead of raising)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _antiderivative(s, beta, half_beta):
    """F(s) = ∫ Ψ_β(-s) ds, F(+∞) = 0 (texvocab.render.volume.volsdf.laplace_antiderivative),
    in float32 as the torch reference computes it (half_beta = -β/2)."""
    e = np.exp(-abs(s) / beta)
    return half_beta * e if s >= 0 else s + half_beta * e


@njit(cache=True, nogil=True, error_model="numpy")
def _optical_depth(s_a, s_b, length, beta, half_beta, flat_below):
    """∫ σ dt over an interval where the SDF runs linearly from s_a to s_b
    (texvocab.render.volume.volsdf.interval_optical_depth), float32."""
    ds = s_a - s_b
    if abs(ds) < flat_below:
        mid = np.float32(0.5) * (s_a + s_b)
        e = np.exp(-abs(mid) / beta)
        density = np.float32(0.5) * e if mid >= 0 else np.float32(1.0) - np.float32(0.5) * e
        return length * density / beta
    return (
        length * ((_antiderivative(s_a, beta, half_beta) - _antiderivative(s_b, beta, half_beta)) / ds) / beta
    )


@njit(cache=True, nogil=True, error_model="numpy")
def parts_that_matter(offsets, t, s, beta, keep, opaque, low, first, end, found):
    """Per ray i (samples t, ŝ (float32) at offsets[i]:offsets[i + 1], at least two): its
    intervals where ŝ may be within ``keep`` β of max(least, 0) (``low``, indexed like the
    interval's first sample), up to where the ray is opaque (optical depth ``opaque`` from
    straight chords); ``first`` and ``end`` (R,): the part is intervals first .. end - 1;
    ``found`` (R,): some interval is low (else first is the last interval and end 1). The
    per-ray form of texvocab.render.guided.residual._part_that_matters, in its float32."""
    b = np.float32(beta)
    half_beta = np.float32(-0.5 * beta)
    flat_below = np.float32(1e-4 * beta)
    margin = np.float32(keep * beta)
    zero = np.float32(0.0)
    for i in range(len(offsets) - 1):
        a, n = offsets[i], offsets[i + 1] - offsets[i]
        least = s[a]
        for j in range(1, n):
            least = min(least, s[a + j])
        lim = max(least, zero) + margin
        f, last_low = -1, -1
        for j in range(n - 1):
            bound = (s[a + j] + s[a + j + 1] - (t[a + j + 1] - t[a + j])) / np.float32(2.0)
            low[a + j] = bound <= lim
            if low[a + j]:
                if f < 0:
                    f = j
                last_low = j
        found[i] = f >= 0
        if f < 0:
            f = n - 2
        deep, cum = n, 0.0
        for j in range(n - 1):
            cum += _optical_depth(s[a + j], s[a + j + 1], t[a + j + 1] - t[a + j], b, half_beta, flat_below)
            if np.float32(cum) >= opaque and j >= f:
                deep = j
                break
        e = min(max(last_low, 0), deep) + 1
        for j in range(e, n - 1):
            low[a + j] = False
        first[i], end[i] = f, e


@njit(cache=True, nogil=True, error_model="numpy")
def refine_counts(first, end, low, offsets, split):
    """The refined samples per ray: its samples first .. end - 1, ``split`` - 1 more in each
    low interval among them, and the sample at end. (R,) int64."""
    out = np.empty(len(first), np.int64)
    for i in range(len(first)):
        c = 1
        for j in range(first[i], end[i]):
            c += split if low[offsets[i] + j] else 1
        out[i] = c
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def refine_fill(first, end, low, offsets, t, d, f, split, new_offsets, t_out, d_out, f_out, new):
    """Write each ray's refined samples (:func:`refine_counts`) at new_offsets: the coarse
    samples with their distance d and face f, the ``split`` - 1 samples inside each low
    interval (t_j + k/split (t_j+1 - t_j)) marked ``new`` (their d and f to be queried)."""
    for i in range(len(first)):
        a, o = offsets[i], new_offsets[i]
        for j in range(first[i], end[i]):
            lo, hi = t[a + j], t[a + j + 1]
            t_out[o], d_out[o], f_out[o], new[o] = lo, d[a + j], f[a + j], False
            o += 1
            if low[a + j]:
                for k in range(1, split):
                    t_out[o], new[o] = lo + np.float32(k / split) * (hi - lo), True
                    o += 1
        e = a + end[i]
        t_out[o], d_out[o], f_out[o], new[o] = t[e], d[e], f[e], False
