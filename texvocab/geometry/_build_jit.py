"""Compiled build of a :class:`texvocab.geometry.surface.SurfaceIndex` (numba, ``nogil``;
``cache`` keeps the machine code in ``__pycache__``): the faces' centroids, the slot of
each face by a top-down median split, the per-slot face table with the box hierarchy,
and the pseudo-normals of faces, edges and vertices. The same arithmetic, in the same
order, as the numpy formulation each replaced (kept in tests/geometry/test_surface_build.py as the
reference). The median split selects each half instead of sorting the segment (ties by
face id instead of by the previous order, a leaf's faces by id): where no two centroids
share a coordinate (any posed body), every node holds the faces it held with the sort
and only the order inside a leaf differs, so every query answer is the same up to ties
between equally near faces."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, inline="always")
def _before(centroids, axis, a, b):
    """Face a comes before face b along ``axis``: by centroid coordinate, then face id."""
    ka, kb = centroids[a, axis], centroids[b, axis]
    return ka < kb or (ka == kb and a < b)


@njit(cache=True, nogil=True)
def _select(order, lo, hi, target, centroids, axis):
    """Rearrange the faces order[lo:hi] so that order[target] is the face a sort by
    :func:`_before` puts there, every face before it in that order ahead of it and every
    face after it behind (Wirth's selection: average O(hi - lo), no sort)."""
    left, right = lo, hi - 1
    while left < right:
        pivot = order[target]
        i, j = left, right
        while i <= j:
            while _before(centroids, axis, order[i], pivot):
                i += 1
            while _before(centroids, axis, pivot, order[j]):
                j -= 1
            if i <= j:
                order[i], order[j] = order[j], order[i]
                i += 1
                j -= 1
        if j < target:
            left = i
        if target < i:
            right = j


@njit(cache=True, nogil=True)
def slot_layout(centroids, size, leaf):
    """(size,) face in each slot, -1 for empty slots, for faces with centroids (F, 3) and
    size = 2^k >= F slots: a segment of faces covering ``cap`` slots is split along its
    longest axis (the first of equal extents) — its first ceil(n / 2) faces by
    (coordinate, face id) take the first cap / 2 slots and the rest the others — down to
    ``leaf`` slots per segment, whose faces fill its first slots by increasing face id.
    Every implicit node of the hierarchy then holds a spatially tight group of faces. The
    split is a selection, not a sort: O(F log F) in all."""
    n = centroids.shape[0]
    order = np.arange(n)
    slot_face = np.full(size, -1, np.int64)
    # explicit stack of segments: (first face, end face, first slot, slots)
    stack = np.empty((128, 4), np.int64)
    stack[0] = (0, n, 0, size)
    top = 1
    lo_x, hi_x = np.empty(3), np.empty(3)
    while top > 0:
        top -= 1
        lo, hi, first, cap = stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3]
        count = hi - lo
        if cap == leaf:
            for r in range(count):  # insertion sort by face id
                face, q = order[lo + r], first + r
                while q > first and slot_face[q - 1] > face:
                    slot_face[q] = slot_face[q - 1]
                    q -= 1
                slot_face[q] = face
            continue
        if count == 0:
            continue
        lo_x[:], hi_x[:] = np.inf, -np.inf
        for i in range(lo, hi):
            f = order[i]
            for a in range(3):
                lo_x[a], hi_x[a] = min(lo_x[a], centroids[f, a]), max(hi_x[a], centroids[f, a])
        axis = 0
        for a in range(1, 3):
            if hi_x[a] - lo_x[a] > hi_x[axis] - lo_x[axis]:
                axis = a
        half = (count + 1) // 2
        if half < count:
            _select(order, lo, hi, lo + half, centroids, axis)
        stack[top] = (lo + half, hi, first + cap // 2, cap // 2)  # right half, after
        stack[top + 1] = (lo, lo + half, first, cap // 2)  # left half, next
        top += 2
    return slot_face


@njit(cache=True, nogil=True)
def face_centroids(vertices, faces):
    """(F, 3) centroid (a + b + c) / 3 of each face."""
    out = np.empty((faces.shape[0], 3))
    for f in range(faces.shape[0]):
        for k in range(3):
            out[f, k] = (vertices[faces[f, 0], k] + vertices[faces[f, 1], k] + vertices[faces[f, 2], k]) / 3.0
    return out


@njit(cache=True, nogil=True)
def slot_tables(vertices, faces, slot_face, degenerate, fan):
    """The per-slot face table (13, S) (rows: a (3), ab (3), ac (3), ab·ab, ab·ac, ac·ac,
    degenerate flag: sin² of the angle at a at most ``degenerate``; empty slots repeat
    face 0) and the box hierarchy: lo, hi (B, 3) of every level concatenated, finest (one
    box per slot) first, node i of level l + 1 bounding nodes i·fan .. i·fan + fan - 1 of
    level l (empty boxes: lo = inf, hi = -inf), and the levels' offsets (L + 1,)."""
    size = slot_face.shape[0]
    table = np.empty((13, size))
    levels, n = 1, size
    total = size
    while n > fan:
        n //= fan
        total += n
        levels += 1
    lo, hi = np.empty((total, 3)), np.empty((total, 3))
    offset = np.zeros(levels + 1, np.int64)
    for s in range(size):
        f = max(slot_face[s], 0)
        a, b, c = vertices[faces[f, 0]], vertices[faces[f, 1]], vertices[faces[f, 2]]
        for k in range(3):
            ab, ac = b[k] - a[k], c[k] - a[k]
            table[k, s], table[3 + k, s], table[6 + k, s] = a[k], ab, ac
        e00 = table[3, s] * table[3, s] + table[4, s] * table[4, s] + table[5, s] * table[5, s]
        e01 = table[3, s] * table[6, s] + table[4, s] * table[7, s] + table[5, s] * table[8, s]
        e11 = table[6, s] * table[6, s] + table[7, s] * table[7, s] + table[8, s] * table[8, s]
        table[9, s], table[10, s], table[11, s] = e00, e01, e11
        table[12, s] = 1.0 if e00 * e11 - e01 * e01 <= degenerate * e00 * e11 else 0.0
        for k in range(3):
            if slot_face[s] < 0:
                lo[s, k], hi[s, k] = np.inf, -np.inf
            else:
                lo[s, k] = min(min(a[k], b[k]), c[k])
                hi[s, k] = max(max(a[k], b[k]), c[k])
    start, n, level = 0, size, 0
    offset[1] = size
    while n > fan:
        parents = n // fan
        for i in range(parents):
            node = start + n + i
            for k in range(3):
                low, high = np.inf, -np.inf
                for j in range(fan):
                    low = min(low, lo[start + i * fan + j, k])
                    high = max(high, hi[start + i * fan + j, k])
                lo[node, k], hi[node, k] = low, high
        start += n
        n = parents
        level += 1
        offset[level + 1] = start + n
    return table, lo, hi, offset


@njit(cache=True, nogil=True)
def pseudo_normals(vertices, faces, edge_of_corner, num_edges):
    """Angle-weighted pseudo-normals (Baerentzen & Aanaes 2005) of a mesh: per face its
    unit normal (F, 3) (zero for zero-area faces), per vertex the sum of its faces'
    normals weighted by their angle there (V, 3), per face edge the sum of the normals of
    the faces on that edge (F, 3, 3) (edge k joins corners k and k + 1; its id
    ``edge_of_corner`` (F·3,) of ``num_edges``), and the orientation: -1.0 when the signed
    volume is negative (faces wound inwards), else 1.0."""
    nf, nv = faces.shape[0], vertices.shape[0]
    face_normal = np.zeros((nf, 3))
    for f in range(nf):
        a, b, c = vertices[faces[f, 0]], vertices[faces[f, 1]], vertices[faces[f, 2]]
        e1x, e1y, e1z = b[0] - a[0], b[1] - a[1], b[2] - a[2]
        e2x, e2y, e2z = c[0] - a[0], c[1] - a[1], c[2] - a[2]
        cx, cy, cz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
        norm = np.sqrt(cx * cx + cy * cy + cz * cz)
        if norm > 0:
            face_normal[f, 0], face_normal[f, 1], face_normal[f, 2] = cx / norm, cy / norm, cz / norm
    vertex_normal = np.zeros((nv, 3))
    corner_sum = np.empty((nv, 3))
    for k in range(3):  # one corner at a time, each summed over the faces in order
        corner_sum[:] = 0.0
        for f in range(nf):
            p = vertices[faces[f, k]]
            q, r = vertices[faces[f, (k + 1) % 3]], vertices[faces[f, (k + 2) % 3]]
            e1x, e1y, e1z = q[0] - p[0], q[1] - p[1], q[2] - p[2]
            e2x, e2y, e2z = r[0] - p[0], r[1] - p[1], r[2] - p[2]
            cx, cy, cz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
            angle = np.arctan2(np.sqrt(cx * cx + cy * cy + cz * cz), e1x * e2x + e1y * e2y + e1z * e2z)
            for j in range(3):
                corner_sum[faces[f, k], j] += angle * face_normal[f, j]
        for v in range(nv):
            for j in range(3):
                vertex_normal[v, j] += corner_sum[v, j]
    edge_sum = np.zeros((num_edges, 3))
    for i in range(nf * 3):
        for j in range(3):
            edge_sum[edge_of_corner[i], j] += face_normal[i // 3, j]
    edge_normal = np.empty((nf, 3, 3))
    for f in range(nf):
        for k in range(3):
            for j in range(3):
                edge_normal[f, k, j] = edge_sum[edge_of_corner[f * 3 + k], j]
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for v in range(nv):
        for j in range(3):
            lo[j], hi[j] = min(lo[j], vertices[v, j]), max(hi[j], vertices[v, j])
    centre = (lo + hi) / 2  # centred: a better-rounded volume
    volume = 0.0
    for f in range(nf):
        a, b, c = vertices[faces[f, 0]], vertices[faces[f, 1]], vertices[faces[f, 2]]
        ax, ay, az = a[0] - centre[0], a[1] - centre[1], a[2] - centre[2]
        bx, by, bz = b[0] - centre[0], b[1] - centre[1], b[2] - centre[2]
        cx, cy, cz = c[0] - centre[0], c[1] - centre[1], c[2] - centre[2]
        volume += ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)
    return face_normal, vertex_normal, edge_normal, -1.0 if volume < 0 else 1.0
