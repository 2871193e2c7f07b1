"""A posed body against masks: silhouette IoU, joint reprojection offsets, and how close
mask pixels' rays pass to the surface (checked against an exact ray-box distance)."""

import numpy as np
import pytest
import torch
from scipy.optimize import minimize_scalar

from texvocab.body import default_body
from texvocab.body.poses import preset
from texvocab.capture.camera import Camera
from texvocab.capture.silhouette import (
    body_silhouette,
    overlap,
    ray_surface_distances,
    reprojection_offsets,
    shell_coverage,
    silhouette_fit,
)


def front_camera(size: int = 96, focal: float = 80.0, distance: float = 3.0) -> Camera:
    """Looks at the origin from +z (the body's front), image +y down."""
    K = [[focal, 0, size / 2], [0, focal, size / 2], [0, 0, 1]]
    return Camera(K, np.diag([1.0, -1.0, -1.0]), [0.0, 0.0, distance], size, size)


@pytest.fixture(scope="module")
def body():
    return default_body()


@pytest.fixture(scope="module")
def frames():
    poses = np.stack([preset("walk")[0], preset("arms_down")[0]])
    trans = np.array([[0.0, 0.2, 0.0], [0.1, 0.2, 0.0]])
    return poses, trans


def test_a_body_against_its_own_silhouette_scores_one_and_a_shifted_one_less(body, frames):
    poses, trans = frames
    cam = front_camera()
    own = [
        body_silhouette(body(torch.as_tensor(p)[None], torch.as_tensor(t)[None]).vertices[0], body.faces, cam)
        for p, t in zip(poses, trans)
    ]
    fit = silhouette_fit(body, poses, trans, cam, iter(own))
    np.testing.assert_array_equal(fit.iou, [1.0, 1.0])
    shifted = silhouette_fit(body, poses, trans + [0.06, 0.0, 0.0], cam, iter(own))
    assert (shifted.iou < 0.9).all() and (shifted.iou > 0.2).all()
    # a pure shift keeps the silhouette's area: as much of it leaves the mask as is missed
    np.testing.assert_allclose(shifted.precision, shifted.recall, atol=0.03)


def test_overlap_counts_pixels():
    a = np.zeros((4, 4), bool)
    b = np.zeros((4, 4), bool)
    a[:2, :2] = True  # 4 pixels
    b[:2, :3] = True  # 6 pixels, 4 shared
    assert overlap(a, b) == pytest.approx((4 / 6, 1.0, 4 / 6))
    assert overlap(a & False, b & False) == (1.0, 1.0, 1.0)


def test_a_mask_of_the_wrong_size_is_refused(body, frames):
    poses, trans = frames
    with pytest.raises(ValueError, match="mask is 10x20, camera '' is 96x96"):
        silhouette_fit(body, poses[:1], trans[:1], front_camera(), [np.zeros((20, 10), bool)])


def test_reprojection_offsets_are_pixel_distances():
    cam = front_camera(focal=100.0)
    joints = np.array([[[0.0, 0.0, 0.0], [0.1, 0.2, 0.0]]])
    np.testing.assert_allclose(reprojection_offsets(cam, joints, joints), [[0.0, 0.0]])
    moved = joints + [0.03, 0.0, 0.0]  # 3 cm sideways at 3 m: 1 px at f = 100
    np.testing.assert_allclose(reprojection_offsets(cam, moved, joints), [[1.0, 1.0]], rtol=1e-9)


def box_mesh(lo, hi):
    """A closed axis-aligned box: 8 vertices, 12 outward triangles."""
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    faces = np.array(
        [
            [0, 1, 3],
            [0, 3, 2],
            [4, 6, 7],
            [4, 7, 5],
            [0, 4, 5],
            [0, 5, 1],
            [2, 3, 7],
            [2, 7, 6],
            [0, 2, 6],
            [0, 6, 4],
            [1, 5, 7],
            [1, 7, 3],
        ]
    )
    return corners, faces


def ray_box_distance(origin, direction, lo, hi) -> float:
    """Exact: the distance to a box is convex along a line, so a bounded scalar search
    finds the ray's closest approach."""

    def dist(t):
        p = origin + t * direction
        return float(np.linalg.norm(np.maximum(np.maximum(lo - p, p - hi), 0.0)))

    return minimize_scalar(dist, bounds=(0.0, 10.0), method="bounded", options={"xatol": 1e-10}).fun


def test_ray_distances_match_the_exact_distance_to_a_box():
    lo, hi = np.array([-0.3, -0.4, -0.2]), np.array([0.3, 0.4, 0.2])
    verts, faces = box_mesh(lo, hi)
    cam = front_camera(size=64, focal=60.0)
    ys, xs = np.mgrid[16:48, 16:48]
    pixels = np.stack([xs.ravel(), ys.ravel()], 1)
    step = 0.004
    got = ray_surface_distances(verts, faces, cam, pixels, max_distance=0.15, step=step)
    origins, dirs = (t.double().numpy() for t in cam.pixel_rays(pixels))
    want = np.array([ray_box_distance(o, d, lo, hi) for o, d in zip(origins, dirs)])
    near = want <= 0.15 - step
    assert (want == 0).sum() > 20 and ((want > 0.02) & near).sum() > 20
    assert np.isinf(got[want > 0.15 + 1e-9]).all()
    assert (got[near] >= want[near] - 1e-9).all()
    assert (got[near] <= want[near] + step / 2 + 1e-9).all()


def test_shell_coverage_grows_with_the_shell(body, frames):
    poses, trans = frames
    cam = front_camera(size=128, focal=110.0)
    own = [
        body_silhouette(body(torch.as_tensor(p)[None], torch.as_tensor(t)[None]).vertices[0], body.faces, cam)
        for p, t in zip(poses, trans)
    ]
    deltas = (0.01, 0.04, 0.1)
    np.testing.assert_array_equal(
        shell_coverage(body, poses, trans, cam, iter(own), deltas, pixel_stride=2), 1.0
    )
    # masks 2 px wider than the body all round (5.5 cm at 3 m): small shells miss some
    wide = [
        np.pad(m, 2)[4:, 2:-2]
        | np.pad(m, 2)[:-4, 2:-2]
        | np.pad(m, 2)[2:-2, 4:]
        | np.pad(m, 2)[2:-2, :-4]
        | m
        for m in own
    ]
    share = shell_coverage(body, poses, trans, cam, iter(wide), deltas, pixel_stride=2)
    assert share.shape == (2, 3)
    assert (np.diff(share, axis=1) > 0).all() and (share[:, 0] < 0.95).all()
    assert (share[:, -1] > 0.99).all()
