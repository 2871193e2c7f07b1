"""Where a pose file's motion goes in a capture's world (``texvocab render --place``).

Pose files are read into the project's +Y-up world (:mod:`texvocab.body.pose_files`), but a
real capture keeps its own: ZJU-MoCap's world is −Z up, so an AMASS walk played there as
it is lies on its side. ``capture`` placement turns the motion rigidly so that its up axis
is the capture's (the mean direction from pelvis to spine3 of the capture's training
poses), its first frame faces the render camera, and its first pelvis stands where the
capture's training poses stand on average; the motion's own path and turns are kept,
relative to its first frame. ``auto`` places only when the capture's up axis is more than
30° off +Y, so synthetic captures (Y up) play pose files exactly as before.
"""

from __future__ import annotations

import numpy as np
import torch

from texvocab.geometry.rotations import rotmat_to_rotvec, rotvec_to_rotmat

PLACEMENTS = ("auto", "capture", "keep")
SPINE3 = 9  # SMPL joint the up axis is measured to, from the pelvis


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation (3, 3) taking unit a to unit b."""
    v, c = np.cross(a, b), float(np.dot(a, b))
    if c < -1 + 1e-9:  # opposite: half a turn about any axis normal to a
        axis = np.cross(a, [1.0, 0, 0] if abs(a[0]) < 0.9 else [0, 1.0, 0])
        axis /= np.linalg.norm(axis)
        return 2 * np.outer(axis, axis) - np.eye(3)
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1 + c)


def capture_up(cap, every: int = 10) -> np.ndarray:
    """(3,) the capture's up axis: the mean pelvis-to-spine3 direction of every ``every``-th
    training pose (the poses are posed in one batch)."""
    frames = list(range(0, max(cap.num_train, 1), every))
    betas = cap.shape()
    betas = None if betas is None else betas.expand(len(frames), -1)
    j = cap.body.forward(torch.as_tensor(cap.poses[frames]), None, betas).joints.double().numpy()
    d = j[:, SPINE3] - j[:, 0]
    up = (d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)).mean(0)
    return up / max(np.linalg.norm(up), 1e-12)


def stand_point(cap) -> np.ndarray:
    """(3,) where the capture's subject stands: the mean pelvis of its training poses."""
    j0 = cap.body.rest_joints[0].double().numpy()
    return np.asarray(cap.trans[: max(cap.num_train, 1)], np.float64).mean(0) + j0


def toward(camera, point: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(3,) the horizontal (normal to ``up``) direction from ``point`` to ``camera``'s
    centre, not normalised (zero when the camera is straight above or below)."""
    want = np.asarray(camera.center, np.float64) - point
    return want - np.dot(want, up) * up


def needs_placing(cap, how: str) -> bool:
    """Whether ``--place how`` turns the motion for this capture."""
    if how not in PLACEMENTS:
        raise ValueError(f"place={how!r}: expected one of {', '.join(PLACEMENTS)}")
    if how != "auto":
        return how == "capture"
    return float(np.dot(capture_up(cap), [0.0, 1.0, 0.0])) < np.cos(np.radians(30))


def place_in_capture(poses: np.ndarray, trans: np.ndarray, pelvis: np.ndarray, cap, camera):
    """``poses`` (T, 24, 3) and ``trans`` (T, 3) of a +Y-up motion turned into ``cap``'s world
    (module docstring), facing ``camera`` at its first frame; ``pelvis`` (3,) is the rest
    pelvis the root rotation turns about. Returns new (poses, trans)."""
    j0 = np.asarray(pelvis, np.float64).reshape(3)
    up = capture_up(cap)
    turn_up = _rotation_between(np.array([0.0, 1.0, 0.0]), up)
    roots = rotvec_to_rotmat(torch.as_tensor(poses[:, 0], dtype=torch.float64)).numpy()
    stand = stand_point(cap)
    # heading: the first frame's facing (the body's +Z), turned up, towards the camera
    face = turn_up @ roots[0] @ np.array([0.0, 0.0, 1.0])
    flat = [face - np.dot(face, up) * up, toward(camera, stand, up)]
    if min(np.linalg.norm(x) for x in flat) > 1e-9:
        a, b = (x / np.linalg.norm(x) for x in flat)
        # a and b are normal to up: the turn is about up (half a turn when opposite)
        heading = 2 * np.outer(up, up) - np.eye(3) if np.dot(a, b) < -1 + 1e-9 else _rotation_between(a, b)
    else:
        heading = np.eye(3)
    R = heading @ turn_up
    out = np.array(poses, np.float64, copy=True)
    out[:, 0] = rotmat_to_rotvec(torch.as_tensor(R[None] @ roots)).numpy()
    pel = np.asarray(trans, np.float64) + j0
    moved = (pel - pel[0]) @ R.T + stand
    return out.astype(poses.dtype), (moved - j0).astype(np.asarray(trans).dtype)
