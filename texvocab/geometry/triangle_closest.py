"""Closest point on triangles, vectorised in float64: Ericson's Voronoi-region tests (Real-
Time Collision Detection, 5.1.5) on a per-face table, zero-area faces tested as their three
edges. The exact search of :mod:`texvocab.geometry.surface` runs them on the faces its box
hierarchy keeps; :mod:`texvocab.geometry._nearest_jit` compiles the same tests."""

from __future__ import annotations

import numpy as np
import torch

DEGENERATE = 1e-10  # sin² of a face's angle at corner a below which it counts as a segment


def face_table(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(13, F) per-face rows: a (3), ab (3), ac (3), ab·ab, ab·ac, ac·ac, degenerate flag."""
    ab, ac = b - a, c - a
    e00, e01, e11 = (ab * ab).sum(1), (ab * ac).sum(1), (ac * ac).sum(1)
    degenerate = e00 * e11 - e01 * e01 <= DEGENERATE * e00 * e11
    return np.ascontiguousarray(np.column_stack([a, ab, ac, e00, e01, e11, degenerate]).T)


def closest_vw(x: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest point a + v ab + w ac of points x (3, P) on faces g (13, P) (see
    :func:`face_table`): Ericson's Voronoi-region tests; zero-area faces use their edges."""
    ap = x - g[0:3]
    ab, ac, e00, e01, e11 = g[3:6], g[6:9], g[9], g[10], g[11]
    d1, d2 = (ab * ap).sum(0), (ac * ap).sum(0)
    d3, d4, d5, d6 = d1 - e00, d2 - e01, d1 - e01, d2 - e11
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        den = va + vb + vc
        v, w = vb / den, vc / den  # face interior; the regions below override it
        m = (va <= 0) & (d4 >= d3) & (d5 >= d6)  # edge BC
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        v, w = np.where(m, 1.0 - t, v), np.where(m, t, w)
        m = (vb <= 0) & (d2 >= 0) & (d6 <= 0)  # edge AC
        v, w = np.where(m, 0.0, v), np.where(m, d2 / (d2 - d6), w)
        m = (d6 >= 0) & (d5 <= d6)  # vertex C
        v, w = np.where(m, 0.0, v), np.where(m, 1.0, w)
        m = (vc <= 0) & (d1 >= 0) & (d3 <= 0)  # edge AB
        v, w = np.where(m, d1 / (d1 - d3), v), np.where(m, 0.0, w)
        m = (d3 >= 0) & (d4 <= d3)  # vertex B
        v, w = np.where(m, 1.0, v), np.where(m, 0.0, w)
        m = (d1 <= 0) & (d2 <= 0)  # vertex A
        v, w = np.where(m, 0.0, v), np.where(m, 0.0, w)
    bad = g[12] > 0
    if bad.any():
        v[bad], w[bad] = closest_on_edges(ap[:, bad], ab[:, bad], ac[:, bad])
    return v, w


def closest_on_edges(ap, ab, ac) -> tuple[np.ndarray, np.ndarray]:
    """(v, w) of the closest point on the three edges; inputs (3, P) relative to corner a."""
    v, w, best = np.zeros(ap.shape[1]), np.zeros(ap.shape[1]), np.full(ap.shape[1], np.inf)
    for start, edge, to_vw in (
        (0, ab, lambda t: (t, 0 * t)),
        (0, ac, lambda t: (0 * t, t)),
        (1, ac - ab, lambda t: (1 - t, t)),
    ):
        rel = ap - ab * start
        len2 = (edge * edge).sum(0)
        t = np.clip(np.divide((rel * edge).sum(0), len2, out=np.zeros_like(len2), where=len2 > 0), 0.0, 1.0)
        d2 = ((rel - t * edge) ** 2).sum(0)
        tv, tw = to_vw(t)
        closer = d2 < best
        v, w, best = np.where(closer, tv, v), np.where(closer, tw, w), np.minimum(d2, best)
    return v, w


def closest_on_triangles(points, a, b, c) -> np.ndarray:
    """Barycentrics (P, 3) of the closest point to points (P, 3) on triangles (a, b, c),
    each (P, 3) or (3,). Zero-area triangles are handled as segments/points."""
    p, a, b, c = (
        np.broadcast_to(
            np.asarray(t.detach().cpu().numpy() if isinstance(t, torch.Tensor) else t, np.float64),
            np.broadcast_shapes(np.shape(points), np.shape(a), np.shape(b), np.shape(c)),
        )
        for t in (points, a, b, c)
    )
    v, w = closest_vw(np.ascontiguousarray(p.T), face_table(a, b, c))
    return np.column_stack([1.0 - v - w, v, w])
