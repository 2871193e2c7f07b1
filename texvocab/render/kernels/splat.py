"""Compiled inner loops of the shell geometry: the splat of
:meth:`texvocab.render.shell.geometry.ShellGeometry.image_bounds` (every pixel inside each
bounding ball's projected box gets the exact ray-sphere entry and exit distance,
min/max-reduced per pixel) and the occupancy grid's bounded distance transform (numba;
``cache`` keeps the machine code in ``__pycache__``)."""

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


@njit(cache=True, nogil=True)
def stamp_distance(cells, offsets, offset_d2, dist2):
    """Bounded Euclidean distance transform: for every voxel within the given offsets
    (O, 3) of a marked voxel cells (U, 3), min-reduce the offset's squared length
    offset_d2 (O,) (voxel units) into dist2 (X, Y, Z) (inf elsewhere: farther than the
    longest offset). Equals scipy's distance_transform_edt² up to that radius."""
    nx, ny, nz = dist2.shape
    for u in range(cells.shape[0]):
        ci, cj, ck = cells[u, 0], cells[u, 1], cells[u, 2]
        for o in range(offsets.shape[0]):
            i, j, k = ci + offsets[o, 0], cj + offsets[o, 1], ck + offsets[o, 2]
            if 0 <= i < nx and 0 <= j < ny and 0 <= k < nz and offset_d2[o] < dist2[i, j, k]:
                dist2[i, j, k] = offset_d2[o]
