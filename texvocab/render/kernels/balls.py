"""Compiled loops of the shell's bounding balls
(:func:`texvocab.render.shell.balls.surface_balls`): every sub-triangle centroid of the
surface sampling visited without materialising the samples (numba; ``cache`` keeps the
machine code in ``__pycache__``)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def subdivisions(v, f, spacing):
    """Per face (F,): n, the sub-triangles per side (radius / spacing rounded up, 1..32),
    and the face's radius (largest centroid-to-corner distance)."""
    F = f.shape[0]
    n_sub = np.empty(F, np.int64)
    radius = np.empty(F)
    for i in range(F):
        cx = (v[f[i, 0], 0] + v[f[i, 1], 0] + v[f[i, 2], 0]) / 3
        cy = (v[f[i, 0], 1] + v[f[i, 1], 1] + v[f[i, 2], 1]) / 3
        cz = (v[f[i, 0], 2] + v[f[i, 1], 2] + v[f[i, 2], 2]) / 3
        r2 = 0.0
        for k in range(3):
            dx, dy, dz = v[f[i, k], 0] - cx, v[f[i, k], 1] - cy, v[f[i, k], 2] - cz
            r2 = max(r2, dx * dx + dy * dy + dz * dz)
        radius[i] = math.sqrt(r2)
        n_sub[i] = min(max(math.ceil(radius[i] / spacing), 1), 32)
    return n_sub, radius


@njit(cache=True, nogil=True)
def visit(v, f, n_sub, mode, lo, width, span, acc, count, centre, spread):
    """One pass over every sub-triangle centroid (surface_samples' samples): mode 0
    min-reduces them into lo (3,); mode 1 adds each into its cube's acc (C, 3) and count
    (C,); mode 2 max-reduces its distance to its cube's centre (C, 3) into spread (C,)."""
    for i in range(f.shape[0]):
        n = n_sub[i]
        a, b, c = f[i, 0], f[i, 1], f[i, 2]
        for half in range(2):  # upward sub-triangles (i + j <= n - 1), then downward
            for si in range(n):
                for sj in range(n - si - half):
                    off = 1.0 / 3.0 if half == 0 else 2.0 / 3.0
                    wv, ww = (si + off) / n, (sj + off) / n
                    wu = 1.0 - wv - ww
                    x = wu * v[a, 0] + wv * v[b, 0] + ww * v[c, 0]
                    y = wu * v[a, 1] + wv * v[b, 1] + ww * v[c, 1]
                    z = wu * v[a, 2] + wv * v[b, 2] + ww * v[c, 2]
                    if mode == 0:
                        lo[0], lo[1], lo[2] = min(lo[0], x), min(lo[1], y), min(lo[2], z)
                        continue
                    kx = int(math.floor((x - lo[0]) / width))
                    ky = int(math.floor((y - lo[1]) / width))
                    kz = int(math.floor((z - lo[2]) / width))
                    cell = (kx * span[1] + ky) * span[2] + kz
                    if mode == 1:
                        acc[cell, 0] += x
                        acc[cell, 1] += y
                        acc[cell, 2] += z
                        count[cell] += 1
                    else:
                        dx, dy, dz = x - centre[cell, 0], y - centre[cell, 1], z - centre[cell, 2]
                        spread[cell] = max(spread[cell], math.sqrt(dx * dx + dy * dy + dz * dz))
