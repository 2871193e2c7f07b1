"""Compiled inner loop of :func:`texvocab.geometry.raster.rasterize`: each triangle walks
the pixels of its bounding box and keeps, per pixel, the nearest covering triangle with a
z-buffer (numba; ``cache`` keeps the machine code in ``__pycache__``)."""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, nogil=True)
def raster_triangles(pix, depth, faces, width, height, face_out, bary_out, depth_out):
    """Projected vertices pix (V, 2) (x, y pixels, float64), their camera depth (V,) and
    triangles faces (F, 3). Per pixel (H·W, row-major; centres at integer coordinates)
    writes the covering triangle nearest the camera: face_out (H·W,) (left as given where
    none), bary_out (H·W, 3) screen-space barycentrics, depth_out (H·W,) its depth
    (perspective-correct: 1/z interpolated; must come in as +inf). Triangles with a
    vertex at depth <= 1e-6 or a zero area are skipped; equal depths go to the later
    triangle."""
    for f in range(faces.shape[0]):
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        if depth[i0] <= 1e-6 or depth[i1] <= 1e-6 or depth[i2] <= 1e-6:
            continue
        ax, ay, bx, by, cx, cy = pix[i0, 0], pix[i0, 1], pix[i1, 0], pix[i1, 1], pix[i2, 0], pix[i2, 1]
        area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        if abs(area) <= 1e-12:
            continue
        x0 = max(int(math.ceil(min(ax, bx, cx))), 0)
        x1 = min(int(math.floor(max(ax, bx, cx))), width - 1)
        y0 = max(int(math.ceil(min(ay, by, cy))), 0)
        y1 = min(int(math.floor(max(ay, by, cy))), height - 1)
        iz0, iz1, iz2 = 1.0 / depth[i0], 1.0 / depth[i1], 1.0 / depth[i2]
        for y in range(y0, y1 + 1):
            for x in range(x0, x1 + 1):
                w0 = (bx - x) * (cy - y) - (by - y) * (cx - x)
                w1 = (cx - x) * (ay - y) - (cy - y) * (ax - x)
                w2 = area - w0 - w1
                b0, b1, b2 = w0 / area, w1 / area, w2 / area
                if b0 < -1e-9 or b1 < -1e-9 or b2 < -1e-9:
                    continue
                z = 1.0 / (b0 * iz0 + b1 * iz1 + b2 * iz2)
                k = y * width + x
                if z <= depth_out[k]:
                    depth_out[k] = z
                    face_out[k] = f
                    bary_out[k, 0], bary_out[k, 1], bary_out[k, 2] = b0, b1, b2
