"""Named pose presets (SMPL axis-angle, radians) used by the demo, tests and viewer.

SMPL frame: +Y up, +Z forward, subject's left = +X. In the T-pose the left arm points
along +X; a rotation about +Z by -a lowers it, about -Y brings it forward. A positive
rotation about +X at a knee bends the shin backwards; a negative one at a hip swings
the thigh forward.
"""

from __future__ import annotations

import numpy as np

from texvocab.body.parts import JOINT_NAMES, NUM_JOINTS

J = {name: i for i, name in enumerate(JOINT_NAMES)}


def _pose(**joints_deg: tuple[float, float, float]) -> np.ndarray:
    pose = np.zeros((NUM_JOINTS, 3), dtype=np.float32)
    for name, deg in joints_deg.items():
        pose[J[name]] = np.radians(deg)
    return pose


PRESETS: dict[str, np.ndarray] = {
    "t_pose": _pose(),
    "a_pose": _pose(left_shoulder=(0, 0, -45), right_shoulder=(0, 0, 45)),
    "arms_down": _pose(
        left_shoulder=(0, 0, -75), right_shoulder=(0, 0, 75), left_elbow=(0, -10, 0), right_elbow=(0, 10, 0)
    ),
    "walk": _pose(
        left_hip=(-30, 0, 0),
        right_hip=(25, 0, 0),
        left_knee=(15, 0, 0),
        right_knee=(45, 0, 0),
        left_shoulder=(0, 25, -70),
        right_shoulder=(0, 25, 70),
        left_elbow=(0, -30, 0),
        right_elbow=(0, 30, 0),
        spine1=(0, 8, 0),
    ),
    "squat": _pose(
        left_hip=(-95, 0, -8),
        right_hip=(-95, 0, 8),
        left_knee=(110, 0, 0),
        right_knee=(110, 0, 0),
        left_ankle=(-10, 0, 0),
        right_ankle=(-10, 0, 0),
        spine1=(20, 0, 0),
        left_shoulder=(0, -80, -10),
        right_shoulder=(0, 80, 10),
    ),
    "arms_up": _pose(
        left_shoulder=(0, 0, 75), right_shoulder=(0, 0, -75), left_collar=(0, 0, 10), right_collar=(0, 0, -10)
    ),
    "kick": _pose(
        right_hip=(-80, 0, 0),
        right_knee=(15, 0, 0),
        left_knee=(10, 0, 0),
        spine1=(-10, 0, 0),
        left_shoulder=(0, 0, -20),
        right_shoulder=(0, 0, 20),
    ),
}

#: Root height offset that keeps the feet near the T-pose floor (metres).
PRESET_TRANS: dict[str, tuple[float, float, float]] = {"squat": (0.0, -0.42, 0.0)}


def preset(name: str) -> tuple[np.ndarray, np.ndarray]:
    """(pose (24, 3), trans (3,)) for a preset name."""
    if name not in PRESETS:
        raise KeyError(f"unknown pose preset {name!r}; choose from {sorted(PRESETS)}")
    return PRESETS[name].copy(), np.asarray(PRESET_TRANS.get(name, (0.0, 0.0, 0.0)), np.float32)
