"""The pose the method is conditioned on: the body's own pose, not which way it faces.

Readers fold the root orientation (ZJU ``Rh``, THUman ``global_orient``) into joint 0, the
pelvis, whose rotation is therefore relative to the capture's world while joints 1–23 are
relative to their parent bones. The vocabulary (its keys, their query, Eqs. 3–6) and the
field's pose input Θ (Eq. 1) read the **root-relative** pose: joint 0's rotation removed
(the identity), joints 1–23 unchanged. The posing — LBS, the posed mesh, the projection of
Eq. 7, the texture back-projection of Eq. 2 — keeps the full global orientation.

Why joint 0 is removed rather than only its heading (the swing–twist yaw about the world's
up axis): the heading needs the capture's true up, and the readers keep each dataset's own
world — ZJU-MoCap's is up = −z, not the y of texvocab's synthetic captures — so heading
removal about y makes ZJU-MoCap 387's novel frames *farther* from the main-body keys than
the global pose does (mean 0.070 against 0.054), while about the true up it gains nothing
over removing joint 0 (0.017 against 0.016, the subject's pelvis tilting 4° on average).
Removal also has no singularity (a heading is undefined for an upside-down body), is
exactly differentiable, and lets a mocap clip in one world query a vocabulary built in
another. HumanNeRF and GauHuman condition their pose networks the same way (the SMPL pose
without its first three entries). What it gives up: a body lying down and one standing
with the same joint angles look alike to the condition.

``global`` is the condition of checkpoints written before this one existed (joint 0 as
the reader folded it); a checkpoint that does not record a condition means ``global``.
"""

from __future__ import annotations

import numpy as np
import torch

from texvocab.body.parts import NUM_JOINTS

#: The conditions a vocabulary and a field can be built with; new runs use the first.
POSE_CONDITIONS: tuple[str, ...] = ("root-relative", "global")

#: SMPL's root joint (the pelvis), the one whose rotation is relative to the world.
ROOT_JOINT = 0


def check_pose_condition(condition: str) -> str:
    """``condition`` if it is one of :data:`POSE_CONDITIONS`, else ValueError naming them."""
    if condition not in POSE_CONDITIONS:
        raise ValueError(
            f"unknown pose condition {condition!r}; expected one of {', '.join(POSE_CONDITIONS)}"
        )
    return condition


def root_relative_pose(pose: torch.Tensor | np.ndarray) -> torch.Tensor:
    """The pose with joint 0's rotation removed: ``(..., 24, 3)`` axis-angle in, the same
    shape, dtype and device out, joints 1–23 bit for bit the input's.

    The same for every orientation of the root (any heading, tilt or turn, of any angle),
    so the result does not depend on which way the body faces. Differentiable: the
    gradient flows to joints 1–23 unchanged and is zero for joint 0.
    """
    pose = torch.as_tensor(pose)
    if pose.ndim < 2 or tuple(pose.shape[-2:]) != (NUM_JOINTS, 3):
        raise ValueError(f"pose: expected shape (..., 24, 3), got {tuple(pose.shape)}")
    root = pose[..., ROOT_JOINT : ROOT_JOINT + 1, :]
    return torch.cat([torch.zeros_like(root), pose[..., ROOT_JOINT + 1 :, :]], dim=-2)


def condition_pose(pose: torch.Tensor | np.ndarray, condition: str) -> torch.Tensor:
    """The pose the vocabulary and the field see under ``condition``: ``(..., 24, 3)``.

    ``root-relative``: :func:`root_relative_pose`; ``global``: the pose itself (the same
    tensor, so old checkpoints compute exactly what they did).
    """
    if check_pose_condition(condition) == "global":
        return torch.as_tensor(pose)
    return root_relative_pose(pose)


def ignored_joints(condition: str) -> tuple[int, ...]:
    """Joints whose rotation ``condition`` does not see: ``(0,)`` for root-relative."""
    return (ROOT_JOINT,) if check_pose_condition(condition) == "root-relative" else ()
