"""Closest point on the posed mesh (Sec. 3.4, Eq. 7): the accelerated search equals the
brute-force reference, hand-computed cases, signs, UV/weights interpolation, degenerate
input."""

import numpy as np
import pytest
import torch
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from texvocab.body import default_body
from texvocab.body.poses import preset
from texvocab.geometry.surface import (
    SurfaceIndex,
    outward_orientation,
    project_brute_force,
    project_to_surface,
)
from texvocab.geometry.triangle_closest import closest_on_triangles

TRI = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
TET = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
TET_FACES = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])  # outward


@pytest.fixture(scope="module")
def body():
    return default_body()


@pytest.fixture(scope="module")
def posed(body):
    pose, trans = preset("walk")
    out = body.forward(torch.as_tensor(pose)[None], torch.as_tensor(trans)[None])
    verts = out.vertices[0].double().numpy()
    faces = body.faces.numpy()
    return verts, faces, SurfaceIndex(verts, faces)


def _surface_samples(verts, faces, n, seed):
    """n random surface points (n, 3) and their faces' unit normals (n, 3)."""
    mesh = trimesh.Trimesh(verts, faces, process=False)
    pts, fid = trimesh.sample.sample_surface(mesh, n, seed=seed)
    return pts, mesh.face_normals[fid]


def _winding_number(points, verts, faces, chunk=64):
    """Generalised winding number (Van Oosterom & Strackee solid angles): (N,)."""
    tri = verts[faces]
    out = np.zeros(len(points))
    for s in range(0, len(points), chunk):
        r = tri[None] - points[s : s + chunk, None, None]  # (P, F, 3, 3)
        a, b, c = r[..., 0, :], r[..., 1, :], r[..., 2, :]
        la, lb, lc = (np.linalg.norm(t, axis=-1) for t in (a, b, c))
        det = (a * np.cross(b, c)).sum(-1)
        den = la * lb * lc + (a * b).sum(-1) * lc + (b * c).sum(-1) * la + (c * a).sum(-1) * lb
        out[s : s + chunk] = 2 * np.arctan2(det, den).sum(1) / (4 * np.pi)
    return out


def test_matches_brute_force_on_posed_body(posed):
    verts, faces, index = posed
    rng = np.random.default_rng(0)
    on, normal = _surface_samples(verts, faces, 900, seed=1)
    shell = on[300:800] + normal[300:800] * rng.uniform(-0.05, 0.05, (500, 1))
    far = on[800:] + rng.normal(size=(100, 3)) * rng.uniform(0.05, 0.3, (100, 1))
    pts = np.concatenate([on[:300], shell, far, verts[::500]])
    fast, ref = index.project(pts), project_brute_force(pts, verts, faces)
    np.testing.assert_allclose(fast.closest, ref.closest, atol=1e-6, rtol=0)
    np.testing.assert_allclose(fast.distance, ref.distance, atol=1e-6, rtol=0)
    assert fast.signed and ref.signed
    assert np.abs(fast.distance[:300]).max() < 1e-9  # sampled on the surface
    differ = fast.face != ref.face  # only ties: the other face is exactly as close
    tri = verts[faces[fast.face[differ]]]
    bary = closest_on_triangles(pts[differ], tri[:, 0], tri[:, 1], tri[:, 2])
    d_other = np.linalg.norm(pts[differ] - np.einsum("nk,nkd->nd", bary, tri), axis=1)
    np.testing.assert_allclose(d_other, np.abs(ref.distance[differ]), atol=1e-12)
    np.testing.assert_allclose(fast.bary.sum(1), 1.0, atol=1e-12)


def test_matches_brute_force_on_a_triangle_soup():
    """Faces from millimetres to metres, far and near points, and an unused vertex next to
    the queries (it is not on the surface, so it must not bound the search)."""
    rng = np.random.default_rng(2)
    centers = rng.uniform(-1, 1, (300, 1, 3))
    sizes = 10.0 ** rng.uniform(-3, 0.3, (300, 1, 1))
    verts = (centers + sizes * rng.normal(size=(300, 3, 3))).reshape(-1, 3)
    faces = np.arange(900).reshape(300, 3)
    pts = rng.uniform(-2, 2, (400, 3))
    verts = np.concatenate([verts, pts[:1] + 1e-4])
    fast, ref = project_to_surface(pts, verts, faces), project_brute_force(pts, verts, faces)
    np.testing.assert_allclose(fast.closest, ref.closest, atol=1e-9, rtol=0)
    np.testing.assert_allclose(fast.distance, ref.distance, atol=1e-9, rtol=0)
    assert not fast.signed and (fast.distance >= 0).all()


def test_kernel_agrees_with_trimesh_per_triangle():
    rng = np.random.default_rng(3)
    a, b, c = rng.normal(size=(3, 5000, 3))
    p = rng.normal(size=(5000, 3)) * 2
    bary = closest_on_triangles(p, a, b, c)
    ours = bary[:, :1] * a + bary[:, 1:2] * b + bary[:, 2:] * c
    theirs = trimesh.triangles.closest_point(np.stack([a, b, c], 1), p)
    np.testing.assert_allclose(
        np.linalg.norm(p - ours, axis=1), np.linalg.norm(p - theirs, axis=1), atol=1e-12
    )
    assert (bary >= -1e-12).all()


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-2, 2), min_size=12, max_size=12))
def test_no_point_of_the_triangle_is_closer(coords):
    a, b, c, p = np.array(coords).reshape(4, 3)
    bary = closest_on_triangles(p[None], a, b, c)[0]
    assert np.isfinite(bary).all() and (bary >= -1e-12).all()
    assert abs(bary.sum() - 1) < 1e-12
    best = np.linalg.norm(p - bary @ np.stack([a, b, c]))
    u, v = np.meshgrid(np.linspace(0, 1, 41), np.linspace(0, 1, 41))
    grid = np.stack([1 - u - v, u, v], -1)[u + v <= 1] @ np.stack([a, b, c])
    assert best <= np.linalg.norm(grid - p, axis=1).min() + 1e-9


@settings(max_examples=80, deadline=None)
@given(st.lists(st.floats(-2, 2), min_size=12, max_size=12), st.sampled_from([1.0, 1e-7, 0.0]))
def test_compiled_search_equals_the_numpy_triangle_test(coords, flatness):
    """The index's compiled region test (nearest_faces) against the numpy one
    (closest_on_triangles) on random triangles, thin (corner c pulled towards the line
    ab by ``flatness``) and exactly collinear ones included."""
    a, b, c, p = np.array(coords).reshape(4, 3)
    c = a + (b - a) * 0.3 + (c - a - (b - a) * 0.3) * flatness
    out = project_to_surface(p[None], np.stack([a, b, c]), np.array([[0, 1, 2]]))
    bary = closest_on_triangles(p[None], a, b, c)[0]
    expect = np.linalg.norm(p - bary @ np.stack([a, b, c]))
    assert out.face[0] == 0
    assert abs(out.distance[0] - expect) <= 1e-12 * (1 + expect)
    np.testing.assert_allclose(out.closest[0], bary @ np.stack([a, b, c]), atol=1e-9)


@pytest.mark.parametrize(
    "point, closest, bary",
    [
        ((-1.0, -1.0, 1.0), (0, 0, 0), (1, 0, 0)),  # vertex regions
        ((2.0, -0.5, 0.0), (1, 0, 0), (0, 1, 0)),
        ((-0.5, 2.0, 0.3), (0, 1, 0), (0, 0, 1)),
        ((0.5, -1.0, 0.5), (0.5, 0, 0), (0.5, 0.5, 0)),  # edge regions
        ((-1.0, 0.25, 0.0), (0, 0.25, 0), (0.75, 0, 0.25)),
        ((1.0, 1.0, 0.2), (0.5, 0.5, 0), (0, 0.5, 0.5)),
        ((0.2, 0.3, 0.7), (0.2, 0.3, 0), (0.5, 0.2, 0.3)),  # face interior
        ((0.25, 0.25, 0.0), (0.25, 0.25, 0), (0.5, 0.25, 0.25)),  # on the surface
    ],
)
def test_single_triangle_regions(point, closest, bary):
    out = project_to_surface(np.array([point]), TRI, np.array([[0, 1, 2]]))
    np.testing.assert_allclose(out.closest[0], closest, atol=1e-12)
    np.testing.assert_allclose(out.bary[0], bary, atol=1e-12)
    np.testing.assert_allclose(out.bary[0] @ TRI, out.closest[0], atol=1e-12)
    assert out.face[0] == 0 and not out.signed  # an open surface has no inside
    assert out.distance[0] == pytest.approx(np.linalg.norm(np.subtract(point, closest)))


def test_tetrahedron_features_and_sign():
    pts = np.array(
        [
            [0.25, 0.25, -0.5],  # below face z=0 -> interior of face 0
            [0.5, -1.0, -1.0],  # off edge (0,1) -> its midpoint
            [-1.0, -1.0, -1.0],  # off vertex 0
            [1.0, 1.0, 1.0],  # off the slanted face, interior -> (1/3, 1/3, 1/3)
            [0.1, 0.2, 0.3],  # inside, nearest the face x = 0
            [0.0, 0.5, 0.5],
        ]
    )  # on an edge, on the surface
    out = project_to_surface(pts, TET, TET_FACES)
    expect = np.array(
        [[0.25, 0.25, 0], [0.5, 0, 0], [0, 0, 0], [1 / 3, 1 / 3, 1 / 3], [0.0, 0.2, 0.3], [0, 0.5, 0.5]]
    )
    np.testing.assert_allclose(out.closest, expect, atol=1e-12)
    np.testing.assert_allclose(out.distance[:4], [0.5, np.sqrt(2), np.sqrt(3), 2 / np.sqrt(3)], atol=1e-12)
    assert out.signed and out.distance[4] == pytest.approx(-0.1) and out.distance[5] == 0
    flipped = project_to_surface(pts, TET, TET_FACES[:, ::-1])  # inward winding
    np.testing.assert_allclose(flipped.distance, out.distance, atol=1e-12)


def test_sign_on_icosphere():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    rng = np.random.default_rng(4)
    pts = rng.uniform(-1.3, 1.3, (3000, 3))
    out = project_to_surface(pts, sphere.vertices, sphere.faces)
    # convex: inside iff behind every face plane
    n = sphere.face_normals
    plane = ((pts[:, None] - sphere.triangles[None, :, 0]) * n[None]).sum(-1)
    inside = (plane < 0).all(1)
    sure = np.abs(out.distance) > 1e-9
    assert out.signed
    np.testing.assert_array_equal((out.distance < 0)[sure], inside[sure])
    np.testing.assert_allclose(np.abs(out.distance[inside]), -plane[inside].max(1), atol=1e-12)


def test_sign_on_posed_body(posed):
    verts, faces, index = posed
    on, normal = _surface_samples(verts, faces, 600, seed=5)
    assert index.project(on - 1e-3 * normal).distance.max() < 0
    assert index.project(on + 1e-3 * normal).distance.min() > 0
    rng = np.random.default_rng(6)
    lo, hi = verts.min(0), verts.max(0)
    pts = np.concatenate([rng.uniform(lo, hi, (300, 3)), on[:300] + rng.normal(0, 0.02, (300, 3))])
    d = index.project(pts).distance
    inside = _winding_number(pts, verts, faces) > 0.5
    sure = np.abs(d) > 1e-6
    np.testing.assert_array_equal((d < 0)[sure], inside[sure])
    assert inside.sum() > 100 and (~inside).sum() > 100
    try:  # trimesh's containment test needs rtree or embree
        contains = trimesh.Trimesh(verts, faces, process=False).contains(pts)
    except ImportError:
        return
    np.testing.assert_array_equal((d < 0)[sure], contains[sure])


def test_uv_and_weights_interpolation(body, posed):
    verts, faces, index = posed
    vt, ft, weights = body.vt.numpy(), body.ft.numpy(), body.weights.numpy()
    # vertices with one UV everywhere (not on a seam) and used by several faces
    pairs = np.unique(np.stack([faces.ravel(), ft.ravel()], 1), axis=0)
    single = np.flatnonzero(np.bincount(pairs[:, 0], minlength=len(verts)) == 1)
    pick = single[:: max(len(single) // 20, 1)]
    out = index.project(verts[pick], vt, ft, weights)
    uv_of_vertex = np.zeros((len(verts), 2))
    uv_of_vertex[faces.ravel()] = vt[ft.ravel()]
    np.testing.assert_allclose(out.uv, uv_of_vertex[pick], atol=1e-9)
    np.testing.assert_allclose(out.weights, weights[pick], atol=1e-7)
    rng = np.random.default_rng(7)
    on, normal = _surface_samples(verts, faces, 500, seed=8)
    out = index.project(on + normal * rng.uniform(-0.03, 0.03, (500, 1)), vt, ft, weights)
    np.testing.assert_allclose(out.weights.sum(1), 1.0, atol=1e-5)
    assert (out.uv >= 0).all() and (out.uv <= 1).all()


def test_degenerate_triangles_and_duplicate_vertices():
    verts = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [0, 1, 0], [1, 1, 0]])
    faces = np.array(
        [
            [0, 1, 2],  # collinear: zero area
            [3, 4, 4],  # a point (duplicate vertices)
            [1, 3, 5],
            [1, 4, 5],
        ]
    )  # the same triangle twice via a duplicate
    rng = np.random.default_rng(9)
    pts = rng.uniform(-1, 3, (400, 3))
    out = project_to_surface(pts, verts, faces)
    ref = project_brute_force(pts, verts, faces)
    for field in (out.bary, out.closest, out.distance):
        assert np.isfinite(field).all()
    np.testing.assert_allclose(out.closest, ref.closest, atol=1e-12)
    np.testing.assert_allclose(out.distance, ref.distance, atol=1e-12)
    seg = project_to_surface(np.array([[1.5, -2.0, 0.5]]), verts, faces[:1])
    np.testing.assert_allclose(seg.closest[0], [1.5, 0, 0], atol=1e-12)
    assert np.isfinite(closest_on_triangles(np.ones((1, 3)), *np.zeros((3, 1, 3)))).all()


def test_max_distance_marks_far_points_invalid(posed):
    verts, faces, index = posed
    rng = np.random.default_rng(10)
    on, normal = _surface_samples(verts, faces, 400, seed=11)
    pts = on + normal * rng.uniform(-0.2, 0.2, (400, 1))
    full = index.project(pts)
    cut = index.project(pts, max_distance=0.05)
    near = np.abs(full.distance) <= 0.05
    np.testing.assert_array_equal(cut.valid, near)
    np.testing.assert_allclose(cut.distance[near], full.distance[near], atol=1e-12)
    assert np.isinf(cut.distance[~near]).all() and np.isnan(cut.closest[~near]).all()
    assert (~near).sum() > 50


def test_torch_in_torch_out_and_index_reuse(posed):
    verts, faces, index = posed
    pts = torch.as_tensor(verts[::700] + 0.01, dtype=torch.float32)
    out = project_to_surface(pts, verts, faces, index=index)
    assert isinstance(out.closest, torch.Tensor) and out.closest.dtype == torch.float32
    assert out.face.dtype == torch.int64
    ref = index.project(pts.double().numpy())
    np.testing.assert_allclose(out.closest.double().numpy(), ref.closest, atol=1e-6)
    with pytest.raises(ValueError):
        project_to_surface(pts, verts, faces[:10], index=index)
    empty = index.project(np.zeros((0, 3)))
    assert empty.face.shape == (0,) and empty.closest.shape == (0, 3)


def test_a_borrowed_layout_gives_the_same_answers_and_relayout_the_own_split(body, posed):
    """An index built on another pose's slot layout (a T-pose's for the walk) answers as
    one built fresh (distances, closest points and signs; faces up to ties between
    equally near faces); relayout() swaps in exactly the fresh build's split."""
    verts, faces, fresh = posed
    rest = SurfaceIndex(body.v_template.double().numpy(), faces)
    lent = SurfaceIndex(verts, faces, like=rest)
    assert lent.borrowed and not fresh.borrowed
    assert not np.array_equal(lent._slot_face, fresh._slot_face)  # a different layout
    rng = np.random.default_rng(3)
    pts = verts[rng.integers(0, len(verts), 3000)] + rng.normal(0, 0.03, (3000, 3))
    a, b = fresh.project(pts), lent.project(pts)
    np.testing.assert_allclose(b.distance, a.distance, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.closest, a.closest, rtol=0, atol=1e-12)
    assert (a.face == b.face).mean() > 0.8  # the rest are ties (shared vertices, edges)
    lent.relayout()
    assert not lent.borrowed and np.array_equal(lent._slot_face, fresh._slot_face)
    np.testing.assert_array_equal(lent.project(pts).face, a.face)
    other = SurfaceIndex(TET, TET_FACES, like=rest)  # other faces: nothing to borrow
    assert not other.borrowed


def test_outward_orientation_of_closed_and_open_meshes(body):
    """+1 for the outward-wound tetrahedron and body, -1 wound inwards, 0 when open."""
    assert outward_orientation(TET, TET_FACES) == 1
    assert outward_orientation(TET, TET_FACES[:, ::-1]) == -1
    assert outward_orientation(TET, TET_FACES[:3]) == 0
    faces = body.faces.numpy()
    assert outward_orientation(body.v_template, faces) == 1
    assert outward_orientation(body.v_template, faces[:, ::-1]) == -1


def test_known_faces_give_the_searched_projection(body, posed):
    """``known`` closest faces skip the search: a point's own answer given back yields the
    same projection bit for bit, a point on a face (a rasterised hit) lies at distance ~0
    with that face's UV and weights, unknown rows (-1) are searched, and a known face
    beyond max_distance is invalid as a searched one is."""
    verts, faces, index = posed
    rng = np.random.default_rng(3)
    near = verts[rng.integers(0, len(verts), 400)] + rng.normal(0, 0.02, (400, 3))
    args = (body.vt.numpy(), body.ft.numpy(), body.weights.numpy())
    searched = index.project(near, *args, max_distance=0.025)
    ok = searched.face >= 0
    assert ok.sum() > 200 and (~ok).sum() > 10
    mixed = np.where(rng.random(400) < 0.5, searched.face, -1)
    again = index.project(near, *args, max_distance=0.025, known=mixed)
    for name in ("face", "bary", "closest", "distance", "uv", "weights"):
        assert np.array_equal(getattr(again, name), getattr(searched, name), equal_nan=True), name
    on, fid = trimesh.sample.sample_surface(trimesh.Trimesh(verts, faces, process=False), 300, seed=4)
    hit = index.project(on, *args, known=fid)
    assert np.array_equal(hit.face, fid) and np.abs(hit.distance).max() < 1e-9
    ref = index.project(on, *args)
    assert np.abs(hit.closest - ref.closest).max() < 1e-9 and np.abs(hit.weights - ref.weights).max() < 1e-6
    far = verts[:5] + np.array([0.0, 0.0, 0.5])
    out = index.project(far, max_distance=0.03, known=np.zeros(5, dtype=np.int64))
    assert (out.face == -1).all() and np.isinf(out.distance).all()


def test_the_search_kernel_matches_the_plain_one_bit_for_bit(posed):
    """nearest_faces (children beyond the best never pushed, sorted as measured) visits
    and drops what nearest_faces_plain does: the same slots, v, w and d² for points on,
    near and far from the body, with and without a search bound."""
    from texvocab.geometry._nearest_jit import nearest_faces, nearest_faces_plain

    verts, _, index = posed
    rng = np.random.default_rng(5)
    base = verts[rng.integers(0, len(verts), 300)]
    d = rng.normal(size=(300, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    along = base[:, None] + np.linspace(-0.04, 0.04, 9)[None, :, None] * d[:, None]  # along rays
    x = np.concatenate([along.reshape(-1, 3), rng.uniform(verts.min(0) - 0.2, verts.max(0) + 0.2, (500, 3))])
    tables = (index._box_lo, index._box_hi, index._box_offset, index._table, index._slot_face)
    for bound in (0.025, np.inf):
        outs = []
        for search in (nearest_faces, nearest_faces_plain):
            out = np.empty(len(x), np.int64), np.empty(len(x)), np.empty(len(x)), np.empty(len(x))
            search(np.ascontiguousarray(x), bound * bound, *tables, *out)
            outs.append(out)
        assert all(np.array_equal(a, b) for a, b in zip(*outs)), bound
        assert (outs[0][0] >= 0).any() and ((outs[0][0] < 0).any() or bound == np.inf)
