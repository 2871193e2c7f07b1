"""Compiled per-ray quadrature of the residual rays at render time
(:mod:`texvocab.render.guided.residual_quadrature`): where along each ray the three field
evaluations go, and the ray's opacity, colour and depth from them, one pass over each ray's
own samples (numba; ``cache`` keeps the machine code in ``__pycache__``; IEEE division,
``error_model="numpy"``, so a non-finite field gives NaN as torch does instead of raising).

The torch reference is :func:`texvocab.render.guided.residual.render_residual`'s groups of
padded arrays (:func:`~texvocab.render.volume.volsdf.linear_sdf_weights`,
``_quantile_columns``, ``_resolve``): the same formulas, in float64 here, so a quantile
that lies within rounding of a column's cumulative weight may pick the neighbouring column.
Each ray i holds ``count[i]`` samples at the front of its row of t, d (R, N) (the rest
repeat the last one, as the padded arrays do); only those are read."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _antiderivative(s, beta):
    """F(s) = ∫ Ψ_β(-s) ds, F(+∞) = 0 (texvocab.render.volume.volsdf.laplace_antiderivative)."""
    e = math.exp(-abs(s) / beta)
    return -0.5 * beta * e if s >= 0 else s - 0.5 * beta * e


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _optical_depth(s_a, s_b, length, beta):
    """∫ σ dt over an interval where the SDF runs linearly from s_a to s_b
    (texvocab.render.volume.volsdf.interval_optical_depth)."""
    ds = s_a - s_b
    if abs(ds) < 1e-4 * beta:
        mid = 0.5 * (s_a + s_b)
        e = math.exp(-abs(mid) / beta)
        density = 0.5 * e if mid >= 0 else 1.0 - 0.5 * e
        return length * density / beta
    return length * ((_antiderivative(s_a, beta) - _antiderivative(s_b, beta)) / ds) / beta


@njit(cache=True, nogil=True, error_model="numpy")
def _column_weights(t, s, n, beta, w):
    """The linear-SDF quadrature's weights of one ray's n samples t, s into w (n,), without
    the part in front of the first sample, the last absorbing what is left where it lies
    inside (residual._column_weights). Returns the optical depth of the whole run."""
    w[0] = 0.0
    tau_sum = 0.0
    for j in range(1, n):
        tau = _optical_depth(s[j - 1], s[j], max(t[j] - t[j - 1], 0.0), beta)
        w[j] = math.exp(-tau_sum) * -math.expm1(-tau)
        tau_sum += tau
    if s[n - 1] < 0:
        w[n - 1] += math.exp(-tau_sum)
    return tau_sum


@njit(cache=True, nogil=True, error_model="numpy")
def _quantile(w, n, q):
    """The first column where the cumulative weight w (n,) (+1e-12 each) reaches q of the
    total (torch.searchsorted's left side, as residual._quantile_columns)."""
    total = 0.0
    for j in range(n):
        total += w[j] + 1e-12
    cum = 0.0
    for j in range(n):
        cum += w[j] + 1e-12
        if cum / total >= q:
            return j
    return n - 1


@njit(cache=True, nogil=True, error_model="numpy")
def quadrature_columns(t, d, count, r0, beta, cap, quantiles, cols):
    """Per ray: the estimate ŝ = d + r0 (cap beyond the shell) over its samples, its
    column weights, and the columns cols (R, Q) where they reach each of ``quantiles``."""
    w = np.empty(t.shape[1], np.float64)
    s = np.empty(t.shape[1], np.float64)
    for i in range(t.shape[0]):
        n = count[i]
        for j in range(n):
            s[j] = d[i, j] + r0[i] if d[i, j] < cap else cap
        _column_weights(t[i], s, n, beta, w)
        for k in range(len(quantiles)):
            cols[i, k] = _quantile(w, n, quantiles[k])


@njit(cache=True, nogil=True, error_model="numpy")
def resolve(t, d, count, cols, knots, sdf3, rgb3, r0, beta, cap, tolerance, acc, color, depth, ok):
    """Per ray (residual._resolve): the SDF d + r with the residual r (and the colour)
    interpolated linearly between the three evaluations at knots (R, 3) (SDF sdf3 (R, 3),
    colour rgb3 (R, 3, 3)), composited in closed form over the ray's samples; ok where the
    residuals (and the probe's r0) agree within ``tolerance`` β and the final weights'
    median lies between the outer evaluations (or the ray shows nothing). Writes acc,
    depth, ok (R,) and color (R, 3)."""
    N = t.shape[1]
    s = np.empty(N, np.float64)
    rgb = np.empty((N, 3), np.float64)
    w = np.empty(N, np.float64)
    for i in range(t.shape[0]):
        n = count[i]
        lo, mid, hi = knots[i, 0], knots[i, 1], knots[i, 2]
        r_lo = sdf3[i, 0] - d[i, cols[i, 0]]
        r_mid = sdf3[i, 1] - d[i, cols[i, 1]]
        r_hi = sdf3[i, 2] - d[i, cols[i, 2]]
        for j in range(n):
            a = min(max((t[i, j] - lo) / max(mid - lo, 1e-12), 0.0), 1.0)
            b = min(max((t[i, j] - mid) / max(hi - mid, 1e-12), 0.0), 1.0)
            c0, c1, c2 = 1.0 - a, a - b, b
            s[j] = d[i, j] + (c0 * r_lo + c1 * r_mid + c2 * r_hi) if d[i, j] < cap else cap
            for c in range(3):
                rgb[j, c] = c0 * rgb3[i, 0, c] + c1 * rgb3[i, 1, c] + c2 * rgb3[i, 2, c]
        tau_sum = _column_weights(t[i], s, n, beta, w)
        # w[n - 1] holds the part the last sample absorbs (ends) on top of its interval's
        ends = math.exp(-tau_sum) if s[n - 1] < 0 else 0.0
        total, place = 0.0, 0.0
        col = np.zeros(3, np.float64)
        for j in range(1, n):
            wj = w[j] - ends if j == n - 1 else w[j]
            total += wj
            place += wj * 0.5 * (t[i, j] + t[i, j - 1])
            for c in range(3):
                col[c] += wj * 0.5 * (rgb[j, c] + rgb[j - 1, c])
        total += ends
        place += ends * t[i, n - 1]
        for c in range(3):
            color[i, c] = col[c] + ends * rgb[n - 1, c]
        acc[i] = total
        depth[i] = place / max(total, 1e-6)
        median = _quantile(w, n, 0.5)
        least = min(r_lo, r_mid, r_hi, r0[i])
        most = max(r_lo, r_mid, r_hi, r0[i])
        finite = r_lo == r_lo and r_mid == r_mid and r_hi == r_hi and r0[i] == r0[i]
        smooth = finite and most - least <= tolerance * beta
        faint = total < 1e-4
        ok[i] = smooth and (faint or (median >= cols[i, 0] and median <= cols[i, 2]))
