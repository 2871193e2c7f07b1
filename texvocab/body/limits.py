"""Sensible per-joint limits (degrees) for the three axis-angle components of each SMPL
joint, used by random poses in synthetic motion and by the viewer's sliders.

Signs follow SMPL's frame (see ``poses.py``): hip flexion forward is negative x, knee
flexion positive x, left-elbow flexion negative y (right: positive y).
"""

from __future__ import annotations

import numpy as np

from texvocab.body.parts import JOINT_NAMES

_SPINE = ((-30, 45), (-30, 30), (-25, 25))
_LIMITS_DEG: dict[str, tuple[tuple[float, float], ...]] = {
    "pelvis": ((-180, 180), (-180, 180), (-180, 180)),
    "left_hip": ((-120, 30), (-45, 45), (-20, 60)),
    "right_hip": ((-120, 30), (-45, 45), (-60, 20)),
    "spine1": _SPINE,
    "spine2": _SPINE,
    "spine3": _SPINE,
    "left_knee": ((0, 150), (-5, 5), (-5, 5)),
    "right_knee": ((0, 150), (-5, 5), (-5, 5)),
    "left_ankle": ((-40, 40), (-20, 20), (-20, 20)),
    "right_ankle": ((-40, 40), (-20, 20), (-20, 20)),
    "left_foot": ((-20, 30), (-10, 10), (-10, 10)),
    "right_foot": ((-20, 30), (-10, 10), (-10, 10)),
    "neck": ((-40, 50), (-60, 60), (-40, 40)),
    "left_collar": ((-15, 15), (-20, 20), (-15, 30)),
    "right_collar": ((-15, 15), (-20, 20), (-30, 15)),
    "head": ((-30, 30), (-40, 40), (-30, 30)),
    "left_shoulder": ((-90, 90), (-100, 40), (-90, 90)),
    "right_shoulder": ((-90, 90), (-40, 100), (-90, 90)),
    "left_elbow": ((-90, 90), (-150, 0), (-5, 5)),
    "right_elbow": ((-90, 90), (0, 150), (-5, 5)),
    "left_wrist": ((-60, 60), (-30, 30), (-70, 70)),
    "right_wrist": ((-60, 60), (-30, 30), (-70, 70)),
    "left_hand": ((-20, 20), (-20, 20), (-40, 40)),
    "right_hand": ((-20, 20), (-20, 20), (-40, 40)),
}

#: (24, 3, 2) lower/upper limit in degrees per joint and axis.
JOINT_LIMITS_DEG = np.array([_LIMITS_DEG[n] for n in JOINT_NAMES], dtype=np.float32)


def clamp_pose(pose: np.ndarray) -> np.ndarray:
    """Clamp axis-angle poses (..., 24, 3) in radians to the limits (root excluded)."""
    lim = np.radians(JOINT_LIMITS_DEG)
    out = np.clip(pose, lim[..., 0], lim[..., 1])
    out[..., 0, :] = pose[..., 0, :]
    return out
