"""Pose sequences as users have them: SMPL (T, 24, 3) / (T, 72), AMASS SMPL-H (T, 156) and
SMPL-X (T, 165) ``.npz`` files, read into SMPL's 24 joints at a chosen frame rate and the
project's +Y-up world.

* SMPL-H and SMPL-X start with the same 22 joints as SMPL (root and 21 body joints); SMPL's
  joints 22 and 23 (the hands) are set to zero, the fingers, jaw and eyes dropped.
* AMASS stores ``mocap_framerate`` (SMPL-H) or ``mocap_frame_rate`` (SMPL-X); the sequence
  is resampled to ``fps`` (quaternion nlerp per joint, linear translation).
* AMASS is Z-up. By default (``up="auto"``) SMPL-H/SMPL-X files are turned to +Y up: the
  world is rotated by -90° about X, root orientation and translation with it (about the
  pelvis, where SMPL's root rotation acts), so a person stands upright with no flag.
* ``root="zero"`` removes the root orientation and translation (the body turns in place).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from texvocab.body.model import POSE_ANGLE_LIMIT, TRANS_LIMIT
from texvocab.body.parts import JOINT_NAMES
from texvocab.errors import AssetError
from texvocab.geometry.rotations import (
    quat_to_rotvec,
    rotmat_to_rotvec,
    rotvec_to_quat,
    rotvec_to_rotmat,
)
from texvocab.io.safe_pickle import read_npz

LAYOUTS = {72: "smpl", 156: "smplh", 165: "smplx"}  # values per frame -> layout
RATE_KEYS = ("mocap_framerate", "mocap_frame_rate", "fps", "frame_rate")
Z_UP_TO_Y_UP = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # -90° about X: z -> y
ACCEPTED = "(T, 24, 3) or (T, 72) SMPL, (T, 156) AMASS SMPL-H or (T, 165) SMPL-X"
#: Highest frame rate a file may state or a sequence be resampled to (frames per second).
MAX_FPS = 1000.0
#: Most frames a resampled sequence may have (20 minutes at 30 fps); counted before any
#: frame is allocated, so a tiny stated frame rate cannot ask for gigabytes.
MAX_FRAMES = 36_000


@dataclass
class PoseSequence:
    """poses (T, 24, 3) float32 SMPL axis-angle; trans (T, 3) float32 metres, +Y up;
    fps: frames per second (None: the file gave none and nothing was resampled);
    layout: "smpl", "smplh" or "smplx"; source_fps: the file's own rate (or None)."""

    poses: np.ndarray
    trans: np.ndarray
    fps: float | None
    layout: str
    source_fps: float | None = None

    def __len__(self) -> int:
        return len(self.poses)


def read_pose_sequence(
    path: str | Path, fps: float | None = 30.0, up: str = "auto", root: str = "keep", pelvis=None
) -> PoseSequence:
    """Read a pose file (see the module docstring); every problem is one
    :class:`AssetError` naming the file and the array.

    Args:
        fps: resample to this rate when the file states its own (None: keep every frame).
        up: "auto" (Z-up for SMPL-H/SMPL-X, as AMASS; Y-up for SMPL), "z" or "y".
        root: "keep" or "zero" (no root orientation or translation).
        pelvis: (3,) rest position of the pelvis joint (the point SMPL's root rotation
            turns about) of the body the poses will drive; default: the default body's.
    """
    path = Path(path)
    if up not in ("auto", "y", "z") or root not in ("keep", "zero"):
        raise ValueError(f"up={up!r} / root={root!r}: expected auto|y|z and keep|zero")
    data = read_npz(path, "pose file (an .npz with 'poses')")
    if "poses" not in data:
        raise AssetError(f"{path}: missing key 'poses'; expected {ACCEPTED}")
    for key in ("poses", "trans"):
        if key in data and not (
            np.issubdtype(data[key].dtype, np.number)
            and not np.issubdtype(data[key].dtype, np.complexfloating)
        ):
            raise AssetError(
                f"{path}: '{key}' holds {data[key].dtype} values; expected real "
                "numbers (axis-angle radians / metres)"
            )
    raw = np.asarray(data["poses"])
    flat = raw.reshape(raw.shape[0], raw.shape[1] * 3) if raw.ndim == 3 and raw.shape[2] == 3 else raw
    if flat.ndim != 2 or flat.shape[1] not in LAYOUTS:
        raise AssetError(f"{path}: 'poses' has shape {raw.shape}; expected {ACCEPTED}")
    layout = LAYOUTS[flat.shape[1]]
    poses = np.zeros((len(flat), 24, 3), dtype=np.float64)
    poses[:, :22] = flat[:, :66].reshape(-1, 22, 3)
    if layout == "smpl":
        poses[:, 22:] = flat[:, 66:72].reshape(-1, 2, 3)
    trans = np.asarray(data.get("trans", np.zeros((len(poses), 3))), dtype=np.float64)
    if trans.shape != (len(poses), 3):
        raise AssetError(f"{path}: 'trans' has shape {trans.shape}, expected ({len(poses)}, 3)")
    _check_values(path, poses, trans)
    rate = _frame_rate(path, data)
    if rate is not None and fps is not None and len(poses) > 1 and abs(rate - fps) > 1e-6:
        count = resampled_count(len(poses), rate, fps)
        if count > MAX_FRAMES:
            raise AssetError(
                f"{path}: {len(poses)} frames at {rate:g} fps resampled to {fps:g} fps would be "
                f"{count:.4g} frames; expected at most {MAX_FRAMES} (is the frame rate right?)"
            )
        poses, trans = _resample(poses, trans, rate, fps)
    if root == "zero":
        poses[:, 0] = 0.0
        trans[:] = 0.0
    elif (up == "z") or (up == "auto" and layout != "smpl"):
        poses, trans = _z_up_to_y_up(poses, trans, pelvis)
    _check_values(path, poses, trans)
    return PoseSequence(
        poses.astype(np.float32),
        trans.astype(np.float32),
        fps if (rate is not None and fps is not None) else rate,
        layout,
        rate,
    )


def _frame_rate(path: Path, data: dict) -> float | None:
    for key in RATE_KEYS:
        if key in data:
            value = np.asarray(data[key]).reshape(-1)
            numeric = value.dtype.kind in "iuf"
            if value.size != 1 or not numeric or not np.isfinite(value[0]) or not 0 < value[0] <= MAX_FPS:
                shown = value[:4].tolist() if value.size else "empty"
                raise AssetError(
                    f"{path}: '{key}' is {shown!r}; expected one frame rate in (0, {MAX_FPS:g}] "
                    "(frames per second)"
                )
            return float(value[0])
    return None


def _check_values(path: Path, poses: np.ndarray, trans: np.ndarray) -> None:
    bad = ~np.isfinite(poses).all(-1)
    if bad.any():
        t, j = (int(i) for i in np.argwhere(bad)[0])
        raise AssetError(f"{path}: 'poses' frame {t} joint {j} ({JOINT_NAMES[j]}) is not finite")
    if not np.isfinite(trans).all():
        raise AssetError(f"{path}: 'trans' is not finite")
    angle = np.linalg.norm(poses, axis=-1)
    if (angle > POSE_ANGLE_LIMIT).any():
        t, j = (int(i) for i in np.argwhere(angle > POSE_ANGLE_LIMIT)[0])
        raise AssetError(
            f"{path}: 'poses' frame {t} joint {j} ({JOINT_NAMES[j]}) turns "
            f"{angle[t, j]:.3g} rad; expected axis-angle of at most 4π"
        )
    if (np.abs(trans) > TRANS_LIMIT).any():
        raise AssetError(
            f"{path}: 'trans' reaches {np.abs(trans).max():.3g} m; expected at most {TRANS_LIMIT:g} m"
        )


def resampled_count(frames: int, rate: float, fps: float) -> float:
    """Frames of a ``frames``-long sequence at ``rate`` resampled to ``fps`` (a float: it may
    be astronomically large, and is compared before anything is allocated)."""
    return np.floor((frames - 1) / rate * fps + 1e-9) + 1


def _resample(poses: np.ndarray, trans: np.ndarray, rate: float, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """(T', 24, 3), (T', 3) at ``fps`` from ``rate``: frame k at time k / fps, quaternion
    nlerp (shortest arc) between the two source frames around it."""
    times = np.arange(int(resampled_count(len(poses), rate, fps))) / fps
    src = np.minimum(times * rate, len(poses) - 1)
    i0 = np.floor(src).astype(int)
    i1 = np.minimum(i0 + 1, len(poses) - 1)
    a = (src - i0)[:, None, None]
    q = rotvec_to_quat(poses).numpy()
    q0, q1 = q[i0], q[i1]
    q1 = np.where((q0 * q1).sum(-1, keepdims=True) < 0, -q1, q1)
    qi = (1 - a) * q0 + a * q1
    qi /= np.linalg.norm(qi, axis=-1, keepdims=True)
    t = (1 - a[:, 0]) * trans[i0] + a[:, 0] * trans[i1]
    return quat_to_rotvec(qi).numpy().astype(np.float64), t


def _z_up_to_y_up(poses: np.ndarray, trans: np.ndarray, pelvis) -> tuple[np.ndarray, np.ndarray]:
    """Rotate the world by -90° about X: root' = R root, trans' = R (J0 + trans) - J0 with
    J0 the rest pelvis (SMPL's root rotation turns the body about J0, not the origin)."""
    if pelvis is None:
        from texvocab.body.default import default_body  # late: loads the embedded body

        pelvis = default_body().rest_joints[0].double().numpy()
    j0 = np.asarray(pelvis, dtype=np.float64).reshape(3)
    R = Z_UP_TO_Y_UP
    root = rotvec_to_rotmat(poses[:, 0]).numpy()
    poses = poses.copy()
    poses[:, 0] = rotmat_to_rotvec(R @ root).numpy()
    return poses, (j0 + trans) @ R.T - j0
