"""Where a pose file's motion goes in a capture's world (``texvocab render --place``).

Pose files are read into the project's +Y-up world (:mod:`texvocab.body.pose_files`), but a
real capture keeps its own: ZJU-MoCap's world is −Z up, so an AMASS walk played there as
it is lies on its side. ``capture`` placement turns the motion rigidly so that its up axis
is the capture's (the mean direction from pelvis to spine3 of the capture's training
poses), its first frame faces the render camera, and its first pelvis stands where the
capture's training poses stand on average; the motion's own path and turns are kept,
relative to its first frame. ``auto`` places only when the capture's up axis is more than
30° off +Y, so synthetic captures (Y up) play pose files exactly as before.

Then the *root* choice (``texvocab render --root``, ``shot --root`` and the viewer's Root
box, all through :func:`place_motion`) says where in that world the motion stands:
``floor`` (default) puts the motion's lowest body point over the whole sequence at the
capture's floor (the lowest body point of its training frames) and its first pelvis over
the capture subject's first training position; ``in-place`` does the same and removes the
horizontal travel; ``facing`` is ``floor`` with the first frame turned about the up axis to
face the camera; ``recorded`` keeps the motion as the file (and ``--place``) has it.
"""

from __future__ import annotations

import numpy as np
import torch

from texvocab.geometry.rotations import rotmat_to_rotvec, rotvec_to_rotmat
from texvocab.pipeline.root_choice import ROOTS

PLACEMENTS = ("auto", "capture", "keep")
Y_UP = np.array([0.0, 1.0, 0.0])
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


def _heading(face: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(3, 3) the turn about ``up`` that takes the horizontal part of ``face`` to the
    horizontal direction ``target`` (identity when either has no horizontal part)."""
    flat = [face - np.dot(face, up) * up, target - np.dot(target, up) * up]
    if min(np.linalg.norm(x) for x in flat) <= 1e-9:
        return np.eye(3)
    a, b = (x / np.linalg.norm(x) for x in flat)
    # a and b are normal to up: the turn is about up (half a turn when opposite)
    return 2 * np.outer(up, up) - np.eye(3) if np.dot(a, b) < -1 + 1e-9 else _rotation_between(a, b)


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
    R = _heading(turn_up @ roots[0] @ np.array([0.0, 0.0, 1.0]), toward(camera, stand, up), up) @ turn_up
    out = np.array(poses, np.float64, copy=True)
    out[:, 0] = rotmat_to_rotvec(torch.as_tensor(R[None] @ roots)).numpy()
    pel = np.asarray(trans, np.float64) + j0
    moved = (pel - pel[0]) @ R.T + stand
    return out.astype(poses.dtype), (moved - j0).astype(np.asarray(trans).dtype)


def lowest_height(cap, poses: np.ndarray, trans: np.ndarray, up: np.ndarray, every: int = 1) -> float:
    """The lowest point along ``up`` of the capture's body (its shape) posed at every
    ``every``-th of ``poses`` (T, 24, 3), ``trans`` (T, 3), in one batch."""
    frames = list(range(0, len(poses), max(1, every)))
    betas = cap.shape()
    betas = None if betas is None else betas.expand(len(frames), -1)
    v = cap.body.forward(torch.as_tensor(poses[frames]), torch.as_tensor(trans[frames]), betas).vertices
    return float((v.double().numpy() @ np.asarray(up, np.float64)).min())


def start_point(cap) -> np.ndarray:
    """(3,) the capture subject's pelvis at its first training frame."""
    return np.asarray(cap.trans[0], np.float64) + cap.body.rest_joints[0].double().numpy()


def place_motion(poses, trans, pelvis, cap, camera, root: str = "floor", place: str = "auto"):
    """``poses`` (T, 24, 3), ``trans`` (T, 3) of a +Y-up motion put into ``cap``'s world:
    turned by ``place`` (:func:`needs_placing`), then stood by ``root`` (module docstring)
    with ``camera`` the one ``facing`` turns to. ``pelvis`` (3,) is the rest pelvis the
    root rotation turns about. Returns new (poses, trans); ``recorded`` with nothing to
    turn returns the inputs."""
    if root not in ROOTS:
        raise ValueError(f"root={root!r}: expected one of {', '.join(ROOTS)}")
    placed = needs_placing(cap, place)
    if placed:
        poses, trans = place_in_capture(poses, trans, pelvis, cap, camera)
    if root == "recorded":
        return poses, trans
    up = capture_up(cap) if placed or needs_placing(cap, "auto") else Y_UP
    j0 = np.asarray(pelvis, np.float64).reshape(3)
    out = np.array(poses, np.float64, copy=True)
    pel = np.asarray(trans, np.float64) + j0
    start = start_point(cap)
    if root == "facing":  # turned to face the camera from where the motion will start
        roots = rotvec_to_rotmat(torch.as_tensor(out[:, 0])).numpy()
        R = _heading(roots[0] @ np.array([0.0, 0.0, 1.0]), toward(camera, start, up), up)
        out[:, 0] = rotmat_to_rotvec(torch.as_tensor(R[None] @ roots)).numpy()
        pel = (pel - pel[0]) @ R.T + pel[0]
    if root == "in-place":  # each frame's pelvis keeps only its height along up
        pel = pel[:1] + np.outer((pel - pel[:1]) @ up, up)
    flat = start - pel[0]
    pel = pel + flat - np.dot(flat, up) * up  # the first pelvis over the subject's start
    moved = pel - j0
    every = max(1, len(out) // 60)
    floor = lowest_height(cap, cap.poses[: max(cap.num_train, 1)], cap.trans[: max(cap.num_train, 1)], up, 10)
    moved = moved + (floor - lowest_height(cap, out, moved, up, every)) * up
    return out.astype(np.asarray(poses).dtype), moved.astype(np.asarray(trans).dtype)
