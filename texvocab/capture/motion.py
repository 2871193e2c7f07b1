"""A seeded procedural motion library: walk, arm raises, squat, torso twist and random
poses within joint limits, stitched into one smooth sequence.

Angles are axis-angle components in degrees per joint (as the presets and the viewer's
sliders); outputs are radians, (T, 24, 3) poses and (T, 3) root translations.
"""

from __future__ import annotations

import numpy as np

from texvocab.body.limits import JOINT_LIMITS_DEG, clamp_pose
from texvocab.body.poses import J

SEGMENTS = ("walk", "arm_raise", "squat", "twist", "random")


def _frames(n: int) -> np.ndarray:
    return np.linspace(0.0, 1.0, n, endpoint=False)


def walk(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """One or two gait cycles in place (treadmill), amplitude and speed randomised."""
    amp = rng.uniform(0.7, 1.1)
    ph = 2 * np.pi * _frames(n) * rng.choice([1.0, 1.5, 2.0])
    deg = np.zeros((n, 24, 3))
    s, c = np.sin(ph), np.cos(ph)
    deg[:, J["left_hip"], 0] = -28 * amp * s
    deg[:, J["right_hip"], 0] = 28 * amp * s
    deg[:, J["left_knee"], 0] = 30 * amp * np.maximum(0, -c) + 8
    deg[:, J["right_knee"], 0] = 30 * amp * np.maximum(0, c) + 8
    deg[:, J["left_shoulder"]] = np.stack([0 * s, 25 * amp * s, -70 + 0 * s], -1)
    deg[:, J["right_shoulder"]] = np.stack([0 * s, 25 * amp * s, 70 + 0 * s], -1)
    deg[:, J["left_elbow"], 1] = -25 - 15 * amp * np.maximum(0, s)
    deg[:, J["right_elbow"], 1] = 25 + 15 * amp * np.maximum(0, -s)
    deg[:, J["spine1"], 1] = 6 * amp * s
    trans = np.zeros((n, 3))
    trans[:, 1] = -0.015 * np.abs(np.cos(ph))
    return np.radians(deg), trans


def arm_raise(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Arms lift sideways and forward with elbow flexion, left and right out of phase."""
    t = _frames(n)
    deg = np.zeros((n, 24, 3))
    up_l = np.sin(np.pi * t) ** 2
    up_r = np.sin(np.pi * (t + rng.uniform(0.2, 0.5))) ** 2
    deg[:, J["left_shoulder"], 2] = -75 + 150 * up_l
    deg[:, J["right_shoulder"], 2] = 75 - 150 * up_r
    deg[:, J["left_shoulder"], 1] = -40 * up_r
    deg[:, J["right_shoulder"], 1] = 40 * up_l
    deg[:, J["left_elbow"], 1] = -120 * np.sin(2 * np.pi * t) ** 2
    deg[:, J["right_elbow"], 1] = 100 * np.sin(2 * np.pi * t + 1.0) ** 2
    deg[:, J["left_wrist"], 2] = 30 * np.sin(2 * np.pi * t)
    return np.radians(deg), np.zeros((n, 3))


def squat(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Down and up once; the root lowers so the feet stay near the floor."""
    depth = rng.uniform(0.6, 1.0) * np.sin(np.pi * _frames(n)) ** 2
    deg = np.zeros((n, 24, 3))
    deg[:, J["left_hip"], 0] = deg[:, J["right_hip"], 0] = -95 * depth
    deg[:, J["left_knee"], 0] = deg[:, J["right_knee"], 0] = 110 * depth
    deg[:, J["left_ankle"], 0] = deg[:, J["right_ankle"], 0] = -12 * depth
    deg[:, J["spine1"], 0] = 20 * depth
    deg[:, J["left_shoulder"]] = np.stack([0 * depth, -80 * depth, -75 + 65 * depth], -1)
    deg[:, J["right_shoulder"]] = np.stack([0 * depth, 80 * depth, 75 - 65 * depth], -1)
    trans = np.zeros((n, 3))
    trans[:, 1] = -0.42 * depth
    return np.radians(deg), trans


def twist(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Torso twist and side/forward bends (diagonal folds on the shirt)."""
    t = 2 * np.pi * _frames(n)
    amp = rng.uniform(0.8, 1.0)
    deg = np.zeros((n, 24, 3))
    for name in ("spine1", "spine2", "spine3"):
        deg[:, J[name], 1] = 22 * amp * np.sin(t)
        deg[:, J[name], 2] = 10 * amp * np.sin(2 * t)
        deg[:, J[name], 0] = 12 * amp * np.maximum(0, np.sin(t + 0.7))
    deg[:, J["left_shoulder"], 2] = -60
    deg[:, J["right_shoulder"], 2] = 60
    deg[:, J["left_elbow"], 1] = -60 * amp
    deg[:, J["right_elbow"], 1] = 60 * amp
    deg[:, J["neck"], 1] = -15 * np.sin(t)
    return np.radians(deg), np.zeros((n, 3))


def random_poses(
    n: int, rng: np.random.Generator, keyframes: int = 4, scale: float = 0.5
) -> tuple[np.ndarray, np.ndarray]:
    """Smoothly interpolated random poses inside ``scale`` × the joint limits."""
    lim = JOINT_LIMITS_DEG
    mid, half = lim.mean(-1), (lim[..., 1] - lim[..., 0]) / 2 * scale
    keys = mid + rng.uniform(-1, 1, (keyframes, 24, 3)) * half
    keys[:, 0] = 0.0  # root orientation stays (the cameras look at a standing person)
    keys[:, [J["left_hip"], J["right_hip"]], 0] = np.clip(
        keys[:, [J["left_hip"], J["right_hip"]], 0], -40, 20
    )  # stay roughly upright
    pos = np.linspace(0, keyframes - 1, n)
    k0 = np.floor(pos).astype(int).clip(0, keyframes - 2) if keyframes > 1 else np.zeros(n, int)
    w = (pos - k0)[:, None, None]
    w = 0.5 - 0.5 * np.cos(np.pi * w)
    deg = keys[k0] * (1 - w) + keys[np.minimum(k0 + 1, keyframes - 1)] * w
    return np.radians(deg), np.zeros((n, 3))


_GENERATORS = {"walk": walk, "arm_raise": arm_raise, "squat": squat, "twist": twist, "random": random_poses}


def make_sequence(
    plan: list[tuple[str, int]], seed: int = 0, blend: int = 4
) -> tuple[np.ndarray, np.ndarray]:
    """Concatenate segments ``[(name, frames), ...]`` with ``blend``-frame cosine joins.

    Returns poses (T, 24, 3) float32 radians (within joint limits) and trans (T, 3).
    """
    rng = np.random.default_rng(seed)
    poses, trans = [], []
    for name, n in plan:
        if name not in _GENERATORS:
            raise ValueError(f"unknown motion segment {name!r}; choose from {SEGMENTS}")
        p, t = _GENERATORS[name](n, rng)
        if poses and blend:
            k = min(blend, n)
            w = (0.5 - 0.5 * np.cos(np.pi * (np.arange(1, k + 1) / (k + 1))))[:, None, None]
            p[:k] = poses[-1][-1] * (1 - w) + p[:k] * w
            t[:k] = trans[-1][-1] * (1 - w[:, 0]) + t[:k] * w[:, 0]
        poses.append(p)
        trans.append(t)
    out = clamp_pose(np.concatenate(poses))
    out[:, [J["left_hand"], J["right_hand"]]] = 0.0  # SMPL-X fits (THUman4.0) have no such joints
    return out.astype(np.float32), np.concatenate(trans).astype(np.float32)


#: The default synthetic capture: training motions first, then novel-pose motions
#: (different amplitudes, combinations and random poses) for the held-out part.
DEFAULT_TRAIN_PLAN = [("walk", 20), ("arm_raise", 16), ("squat", 12), ("twist", 14), ("random", 10)]
DEFAULT_NOVEL_PLAN = [("walk", 10), ("arm_raise", 8), ("twist", 6), ("random", 6)]


def default_motion(seed: int = 0) -> tuple[np.ndarray, np.ndarray, int]:
    """(poses, trans, number of training frames) of the default synthetic capture."""
    p1, t1 = make_sequence(DEFAULT_TRAIN_PLAN, seed)
    p2, t2 = make_sequence(DEFAULT_NOVEL_PLAN, seed + 1000)
    return np.concatenate([p1, p2]), np.concatenate([t1, t2]), len(p1)
