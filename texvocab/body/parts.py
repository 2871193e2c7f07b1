"""SMPL joint names, the paper's body-part table (Table 1) and skinning attention (Sec. 3.4)."""

from __future__ import annotations

from collections.abc import Sequence

import torch

JOINT_NAMES: tuple[str, ...] = (
    "pelvis",
    "left_hip",
    "right_hip",
    "spine1",
    "left_knee",
    "right_knee",
    "spine2",
    "left_ankle",
    "right_ankle",
    "spine3",
    "left_foot",
    "right_foot",
    "neck",
    "left_collar",
    "right_collar",
    "head",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
    "left_hand",
    "right_hand",
)
NUM_JOINTS = len(JOINT_NAMES)
SMPL_PARENTS: tuple[int, ...] = (
    -1,
    0,
    0,
    0,
    1,
    2,
    3,
    4,
    5,
    6,
    7,
    8,
    9,
    9,
    9,
    12,
    13,
    14,
    16,
    17,
    18,
    19,
    20,
    21,
)

#: Paper Table 1: the 5 body parts. Hips 1 and 2 belong to the main body, as in the paper.
BODY_PARTS: dict[str, tuple[int, ...]] = {
    "main_body": (0, 1, 2, 3, 6, 9, 12, 15),
    "left_leg": (4, 7, 10),
    "right_leg": (5, 8, 11),
    "left_arm": (13, 16, 18, 20, 22),
    "right_arm": (14, 17, 19, 21, 23),
}

STRATEGIES = ("part", "joint", "global", "none")


def body_parts(strategy: str = "part") -> dict[str, tuple[int, ...]]:
    """Joint groups for a vocabulary strategy (the paper's ablation).

    ``part``: Table 1's five parts; ``joint``: one part per joint; ``global``: one part
    holding all 24 joints; ``none``: no part at all (the baseline without a vocabulary:
    the field's only condition is the pose Θ).
    """
    if strategy == "part":
        return dict(BODY_PARTS)
    if strategy == "joint":
        return {name: (j,) for j, name in enumerate(JOINT_NAMES)}
    if strategy == "global":
        return {"global": tuple(range(NUM_JOINTS))}
    if strategy == "none":
        return {}
    raise ValueError(f"unknown vocabulary strategy {strategy!r}; expected one of {STRATEGIES}")


def part_membership(parts: Sequence[Sequence[int]], num_joints: int = NUM_JOINTS) -> torch.Tensor:
    """(J, P) 0/1 matrix: entry (j, p) is 1 when joint j belongs to part p."""
    member = torch.zeros(num_joints, len(parts))
    for p, joints in enumerate(parts):
        member[list(joints), p] = 1.0
    return member


def part_attention(weights: torch.Tensor, parts: Sequence[Sequence[int]]) -> torch.Tensor:
    """Skinning-weight attention Ω(x, p) of Sec. 3.4.

    Ω(x, p) = Σ_{j∈p} ω(x, j) / Σ_j ω(x, j), with ω the per-point skinning weights.

    Args:
        weights: (N, J) non-negative skinning weights of each point.
        parts: P joint-index groups.

    Returns:
        (N, P) attention; rows sum to 1 over the joints the parts cover. A row whose
        weights are all zero gets zero attention (not NaN).
    """
    member = part_membership(parts, weights.shape[-1]).to(weights)
    total = weights.sum(-1, keepdim=True)
    safe = torch.where(total > 0, total, torch.ones_like(total))
    return (weights @ member) / safe * (total > 0)
