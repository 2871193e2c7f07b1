"""The bounding balls of the δ-shell (:class:`~texvocab.render.shell.geometry.ShellGeometry`):
the surface sampled so that every surface point lies within r0 of a sample
(:func:`surface_samples`), the samples binned into cubes of side δ, and each bin's ball at
the mean of its samples with radius δ + r0 + its farthest sample. :func:`bounding_balls`
bins the samples in numpy (the reference); :func:`surface_balls`, which the build uses,
computes the same balls with the compiled loops of :mod:`texvocab.render.kernels.balls`.
"""

from __future__ import annotations

import numpy as np

from texvocab.render.kernels.balls import subdivisions, visit

_MAX_CELLS = 1 << 22  # dense cube arrays up to 4M cells (100 MB)


def surface_samples(vertices: np.ndarray, faces: np.ndarray, spacing: float) -> tuple[np.ndarray, float]:
    """Points (P, 3) on the mesh and r0 such that every surface point is within r0 of
    one; r0 <= ``spacing`` unless a face is wider than 32 spacings (faces are cut into
    n² congruent sub-triangles whose centroids are the samples; r0 is the largest
    sub-triangle's centroid-to-corner distance)."""
    tri = vertices[faces]  # (F, 3, 3)
    centroid = tri.mean(1)
    radius = np.sqrt(((tri - centroid[:, None]) ** 2).sum(-1).max(1))
    n_sub = np.clip(np.ceil(radius / spacing), 1, 32).astype(np.int64)
    points = []
    for n in np.unique(n_sub):
        i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
        up, down = i + j <= n - 1, i + j <= n - 2
        vw = (
            np.concatenate(
                [np.stack([i[up] + 1 / 3, j[up] + 1 / 3], 1), np.stack([i[down] + 2 / 3, j[down] + 2 / 3], 1)]
            )
            / n
        )
        bary = np.column_stack([1 - vw.sum(1), vw])
        points.append(np.einsum("sk,fkd->fsd", bary, tri[n_sub == n]).reshape(-1, 3))
    return np.concatenate(points), float((radius / n_sub).max(initial=0.0))


def bounding_balls(samples: np.ndarray, r0: float, width: float) -> tuple[np.ndarray, np.ndarray]:
    """Centres (B, 3) and radii (B,) of balls covering the δ-shell (``width``) of a
    surface sampled by ``samples`` (P, 3) to within r0: the samples binned into cubes of
    side δ, each bin's ball at its mean with radius δ + r0 + its farthest sample. (The
    reference for the compiled :func:`surface_balls`, which the build uses.)"""
    key = np.floor((samples - samples.min(0)) / width).astype(np.int64)
    span = key.max(0) + 1
    _, inverse = np.unique((key[:, 0] * span[1] + key[:, 1]) * span[2] + key[:, 2], return_inverse=True)
    count = np.bincount(inverse)
    centers = np.stack([np.bincount(inverse, samples[:, k]) for k in range(3)], 1)
    centers /= count[:, None]
    spread = np.zeros(len(count))
    np.maximum.at(spread, inverse, np.linalg.norm(samples - centers[inverse], axis=1))
    return centers, spread + r0 + width


def surface_balls(
    vertices: np.ndarray, faces: np.ndarray, spacing: float, width: float
) -> tuple[np.ndarray, np.ndarray, float]:
    """(centres (B, 3), radii (B,), r0): the bounding balls of the ``width``-shell of the
    mesh sampled as :func:`surface_samples` at ``spacing`` does,
    balls in the order of their cubes' flat index (as ``np.unique`` gives them)."""
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    n_sub, radius = subdivisions(v, f, float(spacing))
    r0 = float((radius / n_sub).max(initial=0.0))
    lo = np.full(3, np.inf)
    empty2, empty1 = np.zeros((0, 3)), np.zeros(0)
    dummy_span = np.ones(3, np.int64)
    visit(v, f, n_sub, 0, lo, width, dummy_span, empty2, np.zeros(0, np.int64), empty2, empty1)
    hi = v.max(0) + width  # every cube index of a sample is below (hi - lo) / width
    span = np.floor((hi - lo) / width).astype(np.int64) + 1
    C = int(span.prod())
    if C > _MAX_CELLS:  # a tiny width on a large mesh: bin the samples sparsely instead
        samples, r0 = surface_samples(v, f, spacing)
        return (*bounding_balls(samples, r0, width), r0)
    acc, count = np.zeros((C, 3)), np.zeros(C, np.int64)
    visit(v, f, n_sub, 1, lo, width, span, acc, count, empty2, empty1)
    used = np.flatnonzero(count)
    centre = np.zeros((C, 3))
    centre[used] = acc[used] / count[used, None]
    spread = np.zeros(C)
    visit(v, f, n_sub, 2, lo, width, span, acc, count, centre, spread)
    return centre[used], spread[used] + r0 + width, r0
