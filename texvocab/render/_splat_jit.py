"""Compiled inner loop of :meth:`texvocab.render.shell.ShellGeometry.image_bounds`: every
pixel inside each bounding ball's projected box gets the exact ray-sphere entry and exit
distance, min/max-reduced per pixel (numba; ``cache`` keeps the machine code in
``__pycache__``)."""
from __future__ import annotations

import math

from numba import njit


@njit(cache=True, nogil=True)
def splat_balls(p, rho, x0, x1, y0, y1, dirs, width, near, far):
    """Balls p (B, 3) in the camera frame with radii rho (B,) and pixel boxes
    [x0, x1] x [y0, y1] (B,) (inclusive, clipped to the image); dirs (H*W, 3) unit pixel
    rays. Min-reduces the entry distance into near (H*W,) and max-reduces the exit into
    far for every pixel whose ray meets a ball in front of the camera (exit > 0)."""
    for b in range(p.shape[0]):
        cx, cy, cz, r2 = p[b, 0], p[b, 1], p[b, 2], rho[b] * rho[b]
        c2 = cx * cx + cy * cy + cz * cz
        for y in range(y0[b], y1[b] + 1):
            for x in range(x0[b], x1[b] + 1):
                k = y * width + x
                m = dirs[k, 0] * cx + dirs[k, 1] * cy + dirs[k, 2] * cz
                h2 = r2 - (c2 - m * m)
                if h2 < 0:
                    continue
                root = math.sqrt(h2)
                if m + root <= 0:
                    continue
                if m - root < near[k]:
                    near[k] = m - root
                if m + root > far[k]:
                    far[k] = m + root
