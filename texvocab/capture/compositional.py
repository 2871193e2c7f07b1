"""A compositional synthetic motion: novel poses are new *combinations* of part poses seen in training.

The paper's claim (Sec. 3.3, Table 1): a body-part-wise vocabulary generalises to novel poses better
than a joint-wise or global one because a novel pose is mostly a new combination of part poses that
training showed. Each of the five parts (the main body holds the pelvis, both hips, spine, neck and
head) has a few part motions ``f(u)``, ``u`` in [0, 1] (an amplitude, or a cycle phase for
``walk``/``swing``/``twist``), in degrees per joint like ``motion.py``; right limbs mirror the left
ones, half a cycle later when cyclic.

* **Training** (``COMPOSITIONAL_TRAIN``): a few whole-body combinations, each sweeping its part
  motions through their whole range (0 -> 1 -> 0, or one full cycle).
* **Novel** (``COMPOSITIONAL_NOVEL``): combinations never seen together (squat with arms raised
  sideways, walk with arms forward, kick with one arm up, ...), each part motion sampled inside the
  range training visited (same per-seed amplitudes).

So each part of every novel frame lies close to some training frame's pose of that part under the
paper's d(ρ1, ρ2) = Σ_k (1 − |q1_k·q2_k|) (``part_nearest_distances``), while the whole-body pose is
far from every training frame (``whole_nearest_distance``). Segments are separate takes: smooth
within a segment, with cuts between segments.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from texvocab.body.limits import clamp_pose
from texvocab.body.parts import BODY_PARTS, JOINT_NAMES
from texvocab.body.poses import J
from texvocab.geometry.rotations import rotvec_to_quat

PartMotion = Callable[[np.ndarray, float], np.ndarray]  # (u (n,), amplitude) -> (n, 24, 3) degrees
_LEFT_TO_RIGHT = [
    (i, JOINT_NAMES.index(n.replace("left_", "right_")))
    for i, n in enumerate(JOINT_NAMES)
    if n.startswith("left_")
]
_MIRROR = np.array([1.0, -1.0, -1.0])  # reflection x -> -x of an axis-angle (pseudo)vector
_SPINE = (J["spine1"], J["spine2"], J["spine3"])


def _zeros(u: np.ndarray) -> np.ndarray:
    return np.zeros((len(u), 24, 3))


# -- main body: pelvis, hips, spine, neck, head -------------------------------------------------
def _main_walk(u: np.ndarray, a: float) -> np.ndarray:
    deg, s = _zeros(u), np.sin(2 * np.pi * u)
    deg[:, J["left_hip"], 0], deg[:, J["right_hip"], 0] = -28 * a * s, 28 * a * s
    deg[:, J["spine1"], 1] = 6 * a * s
    return deg


def _main_squat(u: np.ndarray, a: float) -> np.ndarray:
    deg = _zeros(u)
    deg[:, [J["left_hip"], J["right_hip"]], 0] = (-95 * a * u)[:, None]
    deg[:, J["spine1"], 0] = 20 * a * u
    return deg


def _main_twist(u: np.ndarray, a: float) -> np.ndarray:
    deg, t = _zeros(u), 2 * np.pi * u
    deg[:, _SPINE, 1] = (22 * a * np.sin(t))[:, None]
    deg[:, _SPINE, 2] = (10 * a * np.sin(2 * t))[:, None]
    deg[:, _SPINE, 0] = (12 * a * np.maximum(0, np.sin(t + 0.7)))[:, None]
    deg[:, J["neck"], 1] = -15 * a * np.sin(t)
    return deg


def _main_kick(u: np.ndarray, a: float) -> np.ndarray:
    deg = _zeros(u)
    deg[:, J["right_hip"], 0] = -80 * a * u
    deg[:, J["spine1"], 0] = -10 * a * u
    return deg


# -- left leg (knee, ankle, foot) and left arm (collar .. hand); right = mirror --------------------
def _leg_walk(u: np.ndarray, a: float) -> np.ndarray:
    deg, ph = _zeros(u), 2 * np.pi * u
    deg[:, J["left_knee"], 0] = 30 * a * np.maximum(0, -np.cos(ph)) + 8
    deg[:, J["left_ankle"], 0] = 10 * a * np.sin(ph)
    return deg


def _leg_squat(u: np.ndarray, a: float) -> np.ndarray:
    deg = _zeros(u)
    deg[:, J["left_knee"], 0], deg[:, J["left_ankle"], 0] = 110 * a * u, -12 * a * u
    return deg


def _leg_kick(u: np.ndarray, a: float) -> np.ndarray:
    deg = _zeros(u)
    deg[:, J["left_knee"], 0], deg[:, J["left_ankle"], 0] = 20 * a * u, 25 * a * u
    return deg


def _arm_down(u: np.ndarray, a: float) -> np.ndarray:
    deg = _zeros(u)
    deg[:, J["left_shoulder"], 2], deg[:, J["left_elbow"], 1] = -75, -10
    return deg


def _arm_swing(u: np.ndarray, a: float) -> np.ndarray:
    deg, s = _zeros(u), np.sin(2 * np.pi * u)
    deg[:, J["left_shoulder"], 1], deg[:, J["left_shoulder"], 2] = 25 * a * s, -70
    deg[:, J["left_elbow"], 1] = -25 - 15 * a * np.maximum(0, s)
    return deg


def _arm_raise_side(u: np.ndarray, a: float) -> np.ndarray:
    deg = _zeros(u)
    deg[:, J["left_shoulder"], 2], deg[:, J["left_collar"], 2] = -75 + 150 * a * u, 12 * a * u
    deg[:, J["left_elbow"], 1] = -10
    return deg


def _arm_raise_forward(u: np.ndarray, a: float) -> np.ndarray:
    deg = _zeros(u)
    deg[:, J["left_shoulder"], 1], deg[:, J["left_shoulder"], 2] = -80 * a * u, -75 + 65 * a * u
    deg[:, J["left_elbow"], 1] = -10 - 20 * a * u
    return deg


#: Part motions per part kind: name -> (function, cyclic). ``u`` is a phase when cyclic.
PART_MOTIONS: dict[str, dict[str, tuple[PartMotion, bool]]] = {
    "main": {
        "upright": (lambda u, a: _zeros(u), False),
        "walk": (_main_walk, True),
        "squat": (_main_squat, False),
        "twist": (_main_twist, True),
        "kick": (_main_kick, False),
    },
    "leg": {
        "stand": (lambda u, a: _zeros(u), False),
        "walk": (_leg_walk, True),
        "squat": (_leg_squat, False),
        "kick": (_leg_kick, False),
    },
    "arm": {
        "down": (_arm_down, False),
        "swing": (_arm_swing, True),
        "raise_side": (_arm_raise_side, False),
        "raise_forward": (_arm_raise_forward, False),
    },
}
_KIND = {"main_body": "main", "left_leg": "leg", "right_leg": "leg", "left_arm": "arm", "right_arm": "arm"}


@dataclass(frozen=True)
class Combo:
    """One whole-body combination: a part motion name per body part, and a frame count."""

    name: str
    main_body: str
    left_leg: str
    right_leg: str
    left_arm: str
    right_arm: str
    frames: int


#: Training: each part motion swept through its range in these combinations (72 frames).
COMPOSITIONAL_TRAIN = [
    Combo("walk, arms swinging", "walk", "walk", "walk", "swing", "swing", 18),
    Combo("squat, arms forward", "squat", "squat", "squat", "raise_forward", "raise_forward", 14),
    Combo("stand, arms raised sideways", "upright", "stand", "stand", "raise_side", "raise_side", 12),
    Combo("torso twist, arms down", "twist", "stand", "stand", "down", "down", 14),
    Combo("right kick, arms down", "kick", "stand", "kick", "down", "down", 14),
]
#: Novel: part motions from training, in combinations training never showed (30 frames).
COMPOSITIONAL_NOVEL = [
    Combo("squat, arms raised sideways", "squat", "squat", "squat", "raise_side", "raise_side", 6),
    Combo("walk, arms raised forward", "walk", "walk", "walk", "raise_forward", "raise_forward", 6),
    Combo("right kick, left arm raised", "kick", "stand", "kick", "raise_side", "down", 6),
    Combo(
        "torso twist, left arm forward, right arm up",
        "twist",
        "stand",
        "stand",
        "raise_forward",
        "raise_side",
        6,
    ),
    Combo("right kick, arms forward", "kick", "stand", "kick", "raise_forward", "raise_forward", 6),
]


def frame_labels() -> list[str]:
    """Combination name of every frame of ``compositional_motion`` (training first, then novel)."""
    return [c.name for c in COMPOSITIONAL_TRAIN + COMPOSITIONAL_NOVEL for _ in range(c.frames)]


def _combo(c: Combo, u_of: Callable[[str, bool], np.ndarray], amp: dict[str, float]) -> np.ndarray:
    """(frames, 24, 3) degrees; ``u_of(motion name, cyclic)`` gives that motion's (frames,) parameter."""
    deg = np.zeros((c.frames, 24, 3))
    for part, joints in BODY_PARTS.items():
        name = getattr(c, part)
        fn, cyclic = PART_MOTIONS[_KIND[part]][name]
        u = u_of(name, cyclic)
        if part.startswith("right_"):  # mirror of the left limb (half a cycle later when cyclic)
            d, src = _zeros(u), fn(u + 0.5 if cyclic else u, amp[name])
            for left, right in _LEFT_TO_RIGHT:
                d[:, right] = src[:, left] * _MIRROR
        else:
            d = fn(u, amp[name])
        deg[:, list(joints)] = d[:, list(joints)]
    return deg


def compositional_motion(seed: int = 0) -> tuple[np.ndarray, np.ndarray, int]:
    """(poses (T, 24, 3) float32 radians, trans (T, 3) float32, number of training frames).

    Same contract as ``motion.default_motion``: the first ``num_train`` frames are training
    (``COMPOSITIONAL_TRAIN``), the rest novel (``COMPOSITIONAL_NOVEL``). The seed sets each part
    motion's amplitude and the cycle phases (shared by training and novel frames) and the novel
    frames' samples within the visited ranges.
    """
    rng = np.random.default_rng(seed)
    amp = {n: float(rng.uniform(0.85, 1.0)) for kind in PART_MOTIONS.values() for n in kind}
    phase = {n: float(rng.uniform(0, 1)) for n in ("walk", "swing", "twist")}
    phase["swing"] = phase["walk"]  # arms swing with the legs
    degs, depths = [], []
    for c in COMPOSITIONAL_TRAIN:
        k = np.arange(c.frames)
        sweep = np.sin(np.pi * (k + 0.25) / c.frames) ** 2  # 0 -> 1 -> 0, up/down samples interleave

        def train_u(name: str, cyclic: bool, k=k, c=c, sweep=sweep) -> np.ndarray:
            return phase[name] + k / c.frames if cyclic else sweep

        degs.append(_combo(c, train_u, amp))
        depths.append(amp["squat"] * sweep if c.main_body == "squat" else np.zeros(c.frames))
    num_train = sum(len(d) for d in degs)
    for c in COMPOSITIONAL_NOVEL:
        s = 0.5 - 0.5 * np.cos(np.pi * np.linspace(0, 1, c.frames))  # smooth 0 -> 1 within the take
        cache: dict[str, np.ndarray] = {}  # parts sharing a motion (both arms raised) move together

        def novel_u(name: str, cyclic: bool, s=s, cache=cache) -> np.ndarray:
            if name not in cache:
                if cyclic:  # any phase of the cycle was visited in training
                    cache[name] = rng.uniform(0, 1) + rng.uniform(0.3, 0.5) * s
                else:  # the upper part of the swept range, so the part is well away from rest
                    lo, hi = rng.uniform(0.6, 0.97, 2)
                    cache[name] = lo + (hi - lo) * s
            return cache[name]

        degs.append(_combo(c, novel_u, amp))
        depths.append(amp["squat"] * cache["squat"] if "squat" in cache else np.zeros(c.frames))
    poses = clamp_pose(np.radians(np.concatenate(degs)))
    poses[:, [J["left_hand"], J["right_hand"]]] = 0.0  # as make_sequence: SMPL-X fits have none
    trans = np.zeros((len(poses), 3))
    trans[:, 1] = -0.42 * np.concatenate(depths)  # as motion.squat: feet stay near the floor
    return poses.astype(np.float32), trans.astype(np.float32), num_train


# -- the paper's quaternion distance (Sec. 3.3, Eq. 4) -------------------------------------------
def pose_quaternions(poses: np.ndarray) -> np.ndarray:
    """Axis-angle (..., 3) radians -> unit quaternions (..., 4) as (w, x, y, z)."""
    return rotvec_to_quat(torch.as_tensor(np.asarray(poses, dtype=np.float64))).numpy()


def pairwise_part_distance(poses_a: np.ndarray, poses_b: np.ndarray, joints) -> np.ndarray:
    """(N, M) d(ρ_a, ρ_b) = Σ_{k∈joints} (1 − |q_a,k · q_b,k|) for poses (N, 24, 3), (M, 24, 3)."""
    qa, qb = pose_quaternions(poses_a)[:, list(joints)], pose_quaternions(poses_b)[:, list(joints)]
    return (1.0 - np.abs(np.einsum("njc,mjc->nmj", qa, qb)).clip(max=1.0)).sum(-1)


def part_nearest_distances(poses_novel: np.ndarray, poses_train: np.ndarray) -> np.ndarray:
    """(N, 5): per novel frame and body part (``BODY_PARTS`` order), distance to the nearest training
    frame's pose of that part (each part may pick a different training frame)."""
    return np.stack(
        [pairwise_part_distance(poses_novel, poses_train, j).min(1) for j in BODY_PARTS.values()], 1
    )


def whole_nearest_distance(poses_novel: np.ndarray, poses_train: np.ndarray) -> np.ndarray:
    """(N,): distance of each novel frame to the nearest training frame with all 24 joints as one part
    (= the sum over the five parts for one common training frame)."""
    return pairwise_part_distance(poses_novel, poses_train, range(len(JOINT_NAMES))).min(1)
