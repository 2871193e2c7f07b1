"""Compiled build of :class:`texvocab.geometry.surface.SurfaceIndex`'s hierarchy: the slot
of each face, by a top-down median split (numba; ``cache`` keeps the machine code in
``__pycache__``)."""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def slot_layout(centroids, size, leaf):
    """(size,) face in each slot, -1 for empty slots, for faces with centroids (F, 3) and
    size = 2^k >= F slots: a segment of faces covering ``cap`` slots is sorted (stably)
    along its longest axis (the first of equal extents), its first ceil(n / 2) faces take
    the first cap / 2 slots and the rest the others, down to ``leaf`` slots per segment,
    whose faces fill its first slots in order. Every implicit node of the hierarchy then
    holds a spatially tight group of faces."""
    n = centroids.shape[0]
    order = np.arange(n)
    slot_face = np.full(size, -1, np.int64)
    # explicit stack of segments: (first face, end face, first slot, slots)
    stack = np.empty((128, 4), np.int64)
    stack[0] = (0, n, 0, size)
    top = 1
    while top > 0:
        top -= 1
        lo, hi, first, cap = stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3]
        count = hi - lo
        if cap == leaf:
            for r in range(count):
                slot_face[first + r] = order[lo + r]
            continue
        if count == 0:
            continue
        axis, extent = 0, -1.0
        for a in range(3):
            c_min, c_max = np.inf, -np.inf
            for i in range(lo, hi):
                v = centroids[order[i], a]
                c_min, c_max = min(c_min, v), max(c_max, v)
            if c_max - c_min > extent:
                axis, extent = a, c_max - c_min
        key = np.empty(count)
        for i in range(count):
            key[i] = centroids[order[lo + i], axis]
        perm = np.argsort(key, kind="mergesort")
        order[lo:hi] = order[lo:hi][perm]
        half = (count + 1) // 2
        stack[top] = (lo + half, hi, first + cap // 2, cap // 2)  # right half, after
        stack[top + 1] = (lo, lo + half, first, cap // 2)  # left half, next
        top += 2
    return slot_face
