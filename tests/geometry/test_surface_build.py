"""The compiled build of a SurfaceIndex (texvocab.geometry._build_jit) against the numpy
formulation it replaced: the same face table, boxes and pseudo-normals bit for bit, and
the median split's layout against a numpy statement of its rule (ties by face id)."""

import math

import numpy as np
import torch

from texvocab.body import default_body
from texvocab.body.poses import preset
from texvocab.geometry.surface import SurfaceIndex, _slot_layout
from texvocab.geometry.triangle_closest import face_table

FAN = 4


def reference_slot_layout(centroids: np.ndarray, leaf: int = 4) -> np.ndarray:
    """Level by level in numpy: each segment sorted by (coordinate along its longest axis,
    face id), its first ceil(n / 2) faces to the left half; a leaf's faces by face id."""
    n = len(centroids)
    size = 1 << max(int(np.ceil(np.log2(max(n, leaf)))), 2)
    order, seg, cap = np.arange(n), np.zeros(n, np.int64), size
    while True:
        counts = np.bincount(seg, minlength=size // cap)
        starts = np.cumsum(counts) - counts
        if cap == leaf:
            perm = np.lexsort((order, seg))
            order, seg = order[perm], seg[perm]
            slot_face = np.full(size, -1)
            slot_face[seg * leaf + np.arange(n) - starts[seg]] = order
            return slot_face
        c = centroids[order]
        used = starts[counts > 0]
        axis = np.zeros(len(counts), np.int64)
        axis[counts > 0] = (np.maximum.reduceat(c, used) - np.minimum.reduceat(c, used)).argmax(1)
        perm = np.lexsort((order, c[np.arange(n), axis[seg]], seg))
        order, seg = order[perm], seg[perm]
        rank = np.arange(n) - starts[seg]
        seg = 2 * seg + (rank >= (counts[seg] + 1) // 2)
        cap //= 2


def reference_boxes(slot_tri: np.ndarray, empty: np.ndarray):
    """Box levels, finest (one per slot) first; a parent bounds its FAN children."""
    lo = np.where(empty[:, None], np.inf, slot_tri.min(1))
    hi = np.where(empty[:, None], -np.inf, slot_tri.max(1))
    levels = [(lo, hi)]
    while len(lo) > FAN:
        lo, hi = lo.reshape(-1, FAN, 3).min(1), hi.reshape(-1, FAN, 3).max(1)
        levels.append((lo, hi))
    offset = np.cumsum([0] + [len(lo) for lo, _ in levels])
    return np.concatenate([lo for lo, _ in levels]), np.concatenate([h for _, h in levels]), offset


def _scatter_add(index, values, size):
    return np.stack([np.bincount(index, values[:, c], minlength=size) for c in range(3)], 1)


_ATAN2 = np.frompyfunc(math.atan2, 2, 1)


def reference_pseudo_normals(vertices: np.ndarray, faces: np.ndarray, inverse, edges):
    """Angle-weighted pseudo-normals of faces, vertices and face edges; orientation sign."""
    tri = vertices[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(cross, axis=1, keepdims=True)
    face_normal = np.divide(cross, norm, out=np.zeros_like(cross), where=norm > 0)
    vertex_normal = np.zeros_like(vertices)
    for k in range(3):
        e1, e2 = tri[:, (k + 1) % 3] - tri[:, k], tri[:, (k + 2) % 3] - tri[:, k]
        # libm's atan2, as the compiled build calls it: numpy's own arctan2 (2.4, SIMD)
        # differs from it in the last bit on about 7% of inputs
        angle = _ATAN2(np.linalg.norm(np.cross(e1, e2), axis=1), (e1 * e2).sum(1)).astype(float)
        vertex_normal += _scatter_add(faces[:, k], angle[:, None] * face_normal, len(vertices))
    edge_sum = _scatter_add(inverse, np.repeat(face_normal, 3, axis=0), edges)
    t = tri - (vertices.min(0) + vertices.max(0)) / 2
    volume = (t[:, 0] * np.cross(t[:, 1], t[:, 2])).sum()
    return (face_normal, vertex_normal, edge_sum[inverse].reshape(-1, 3, 3), -1.0 if volume < 0 else 1.0)


def _meshes():
    body = default_body()
    for name in ("walk", "squat"):
        pose, _ = preset(name)
        posed = body.forward(torch.as_tensor(pose, dtype=torch.float32).reshape(1, 24, 3))
        yield posed.vertices[0].double().numpy(), body.faces.numpy(), False
    rng = np.random.default_rng(0)
    for v, f in ((50, 77), (30, 5), (9, 1), (200, 1000)):
        verts = np.round(rng.normal(size=(v, 3)), 1)  # shared coordinates: ties
        faces = rng.integers(0, v, (f, 3))
        faces[: max(1, f // 5), 2] = faces[: max(1, f // 5), 1]  # zero-area faces
        yield verts, faces, True


def test_compiled_build_equals_the_numpy_build_bit_for_bit():
    """Face table, boxes, offsets and pseudo-normals (face, edge, vertex) are the same
    numbers as the numpy build gave, on posed bodies and on random meshes with zero-area
    faces; the orientation sign agrees."""
    from texvocab.geometry.surface import _edge_topology

    for verts, faces, zero_area in _meshes():
        index = SurfaceIndex(verts, faces)
        slot_tri = verts[faces][np.maximum(index._slot_face, 0)]
        table = face_table(*(slot_tri[:, k] for k in range(3)))
        assert np.array_equal(index._table, table)
        lo, hi, offset = reference_boxes(slot_tri, index._slot_face < 0)
        assert np.array_equal(index._box_lo, lo) and np.array_equal(index._box_hi, hi)
        assert np.array_equal(index._box_offset, offset)
        inverse, edges, _ = _edge_topology(index.faces, len(verts))
        fn, vn, en, orientation = reference_pseudo_normals(verts, index.faces, inverse, edges)
        assert np.array_equal(index._face_normal, fn)
        assert np.array_equal(index._vertex_normal, vn)
        assert np.array_equal(index._edge_normal, en)
        assert index._orientation == orientation
        assert index._table[12].any() == zero_area  # the degenerate flag is exercised


def test_median_split_layout_follows_its_rule_with_ties():
    """The selection-based split gives the layout of a full sort by (coordinate, face id),
    on the body and on centroids with equal coordinates; every face gets one slot."""
    body = default_body()
    tri = body.v_template.double().numpy()[body.faces.numpy()]
    assert np.array_equal(_slot_layout(tri.mean(1)), reference_slot_layout(tri.mean(1)))
    rng = np.random.default_rng(0)
    for n in (1, 3, 4, 5, 17, 100, 1000, 5000):
        c = rng.normal(size=(n, 3))
        c[: n // 3, 1] = 0.5  # equal keys: ties decided by face id
        c[: n // 4, 0] = c[: n // 4, 2] = 0.0
        c[n // 2 :, :] = np.round(c[n // 2 :], 1)
        layout = _slot_layout(c)
        assert np.array_equal(layout, reference_slot_layout(c))
        assert sorted(layout[layout >= 0].tolist()) == list(range(n))


def test_faces_outside_the_vertex_range_are_refused():
    """The compiled build reads vertices[faces] without bounds checks: the index refuses
    out-of-range faces with a ValueError instead of reading past the array."""
    import pytest

    verts = np.zeros((3, 3))
    for bad in ([[0, 1, 3]], [[0, -1, 2]]):
        with pytest.raises(ValueError, match="faces index vertices 0..2"):
            SurfaceIndex(verts, np.array(bad))
