"""A pose file's motion placed in a capture whose world is not Y up (ZJU-MoCap is −Z up):
upright in that world, its first frame facing the camera, standing where the capture's
subject stands, its own path kept; a Y-up capture plays it as it is."""

import dataclasses

import numpy as np
import pytest
import torch

from texvocab.body.poses import preset
from texvocab.capture import open as open_capture
from texvocab.capture.camera import Camera
from texvocab.geometry.rotations import rotmat_to_rotvec, rotvec_to_rotmat
from texvocab.pipeline.clip_placement import capture_up, needs_placing, place_in_capture

Y_TO_MINUS_Z = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # +Y -> -Z


def turned(cap, R):
    """``cap`` with its whole world turned by R (poses' roots, translations, cameras)."""
    j0 = cap.body.rest_joints[0].double().numpy()
    roots = rotvec_to_rotmat(torch.as_tensor(cap.poses[:, 0], dtype=torch.float64)).numpy()
    poses = cap.poses.copy()
    poses[:, 0] = rotmat_to_rotvec(torch.as_tensor(R[None] @ roots)).numpy()
    trans = ((cap.trans + j0) @ R.T - j0).astype(cap.trans.dtype)
    cams = [Camera(c.K, c.R @ R.T, c.t, c.width, c.height, c.dist, c.name) for c in cap.cameras]
    return dataclasses.replace(cap, poses=poses, trans=trans, cameras=cams)


@pytest.fixture(scope="module")
def zju_like(capture):
    return turned(open_capture(capture), Y_TO_MINUS_Z)


def test_up_axis_and_when_to_place(capture, zju_like):
    assert np.dot(capture_up(zju_like), [0, 0, -1]) > 0.95
    assert needs_placing(zju_like, "auto") and not needs_placing(open_capture(capture), "auto")
    assert needs_placing(open_capture(capture), "capture") and not needs_placing(zju_like, "keep")


def test_the_walk_stands_up_faces_the_camera_and_keeps_its_path(zju_like):
    walk, _ = preset("walk")
    n = 5
    poses = np.repeat(np.asarray(walk, np.float64)[None], n, 0)
    trans = np.stack([np.array([0.0, 0.0, 0.3 * i]) for i in range(n)])  # walks 30 cm a frame
    body, cam = zju_like.body, zju_like.cameras[0]
    j0 = body.rest_joints[0].double().numpy()
    p, t = place_in_capture(poses, trans, j0, zju_like, cam)
    joints = body.forward(torch.as_tensor(p), torch.as_tensor(t)).joints.double().numpy()
    up = capture_up(zju_like)
    spine = joints[0, 9] - joints[0, 0]
    assert np.dot(spine / np.linalg.norm(spine), up) > 0.95
    stand = zju_like.trans[: zju_like.num_train].mean(0) + j0
    np.testing.assert_allclose(joints[0, 0], stand, atol=1e-6)
    facing = rotvec_to_rotmat(torch.as_tensor(p[0, 0])).numpy() @ [0, 0, 1.0]
    want = cam.center - stand
    flat = [x - np.dot(x, up) * up for x in (facing, want)]
    assert np.dot(*(x / np.linalg.norm(x) for x in flat)) > 0.99
    steps = np.linalg.norm(np.diff(joints[:, 0], axis=0), axis=1)
    np.testing.assert_allclose(steps, 0.3, atol=1e-6)


def test_the_viewer_timeline_places_a_pose_file_as_render_does(zju_like, capture, tmp_path):
    from pose_file_cases import amass_file

    from texvocab_viewer.panels.pose import PoseSequence

    amass_file(tmp_path / "walk.npz", frames=5)
    placed = PoseSequence.load(str(tmp_path / "walk.npz"), zju_like)
    plain = PoseSequence.load(str(tmp_path / "walk.npz"), open_capture(capture))
    body = zju_like.body
    for seq, up in ((placed, capture_up(zju_like)), (plain, np.array([0.0, 1.0, 0.0]))):
        j = body.forward(torch.as_tensor(seq.poses[:1]), torch.as_tensor(seq.trans[:1])).joints[0]
        spine = (j[9] - j[0]).double().numpy()
        assert np.dot(spine / np.linalg.norm(spine), up) > 0.95


def test_the_viewer_orbits_about_the_captures_up_axis(zju_like, capture):
    from texvocab_viewer.gl.camera import OrbitCamera, orbit_for

    plain = OrbitCamera(target=np.zeros(3), distance=2.0)
    np.testing.assert_allclose(plain.eye, [0, 0, 2.0])  # +y up, yaw 0 on +z: as before
    assert orbit_for(None).up @ [0, 1, 0] == 1 and orbit_for(open_capture(capture)).up @ [0, 1, 0] == 1
    cam = orbit_for(zju_like)
    up = capture_up(zju_like)
    np.testing.assert_allclose(cam.up, up)
    for yaw, pitch in ((0, 0), (70, 20), (-120, -40)):
        cam.yaw, cam.pitch = yaw, pitch
        R = cam.to_texvocab_camera(64, 48).R
        # the image's down axis stays in the plane of -up and the view axis: no roll
        assert abs(np.dot(R[0], up)) < 1e-9
        elevation = np.degrees(np.arcsin(np.dot((cam.eye - cam.target) / cam.distance, up)))
        assert elevation == pytest.approx(pitch, abs=1e-6)
    cam.yaw, cam.pitch = 0, 0
    to_camera = zju_like.cameras[0].center - cam.target
    flat = to_camera - np.dot(to_camera, up) * up
    assert np.dot(cam.front, flat / np.linalg.norm(flat)) > 0.999


def _floating_walk(n=6, lift=1.2):
    walk, _ = preset("walk")
    poses = np.repeat(np.asarray(walk, np.float64)[None], n, 0)
    # walks 30 cm a frame along +X, 1.2 m above where a floor would be, 2 m off to the side
    trans = np.stack([np.array([2.0 + 0.3 * i, lift, -1.5]) for i in range(n)])
    return poses, trans


def _lowest(cap, p, t, up):
    v = cap.body.forward(torch.as_tensor(p), torch.as_tensor(t)).vertices.double().numpy()
    return (v @ up).min()


@pytest.mark.parametrize("world", ["y_up", "zju_like"])
def test_root_floor_stands_the_motion_on_the_captures_floor_where_its_subject_starts(
    world, capture, zju_like
):
    from texvocab.pipeline.clip_placement import place_motion, start_point

    cap = zju_like if world == "zju_like" else open_capture(capture)
    up = capture_up(cap) if world == "zju_like" else np.array([0.0, 1.0, 0.0])
    j0 = cap.body.rest_joints[0].double().numpy()
    poses, trans = _floating_walk()
    floor = _lowest(cap, cap.poses[: cap.num_train], cap.trans[: cap.num_train], up)
    start = start_point(cap)
    results = {}
    for root in ("floor", "in-place", "facing"):
        p, t = place_motion(poses, trans, j0, cap, cap.cameras[1], root)
        results[root] = (p, t)
        assert abs(_lowest(cap, p, t, up) - floor) < 1e-4, root  # the lowest foot on the floor
        off = (t[0] + j0) - start
        np.testing.assert_allclose(off - np.dot(off, up) * up, 0, atol=1e-6)  # starts where the subject does
    pel = results["floor"][1] + j0
    travel = np.linalg.norm(np.diff(pel, axis=0), axis=1)
    np.testing.assert_allclose(travel, 0.3, atol=1e-6)  # floor keeps the path
    pel = results["in-place"][1] + j0
    flat = pel - np.outer(pel @ up, up)
    np.testing.assert_allclose(flat - flat[0], 0, atol=1e-6)  # in-place: no travel
    p, t = results["facing"]
    facing = rotvec_to_rotmat(torch.as_tensor(p[0, 0])).numpy() @ [0, 0, 1.0]
    want = cap.cameras[1].center - (t[0] + j0)
    a, b = (x - np.dot(x, up) * up for x in (facing, want))
    assert np.dot(a, b) / np.linalg.norm(a) / np.linalg.norm(b) > 0.999
    if world == "y_up":  # recorded: the file's motion untouched
        p, t = place_motion(poses, trans, j0, cap, cap.cameras[1], "recorded")
        np.testing.assert_array_equal(t, trans)
        np.testing.assert_array_equal(p, poses)
    with pytest.raises(ValueError, match="root='up': expected one of"):
        place_motion(poses, trans, j0, cap, cap.cameras[1], "up")
