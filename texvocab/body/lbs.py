"""Functional linear blend skinning core (SMPL-style, Loper et al. 2015).

Everything here is a pure function of tensors; :class:`texvocab.body.model.BodyModel`
holds the arrays and calls these. Shapes are given as ``(B, J, 3)`` etc.
"""

from __future__ import annotations

import torch

from texvocab.geometry.rotations import rotvec_to_rotmat


def forward_kinematics(
    rotmats: torch.Tensor, joints: torch.Tensor, parents: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Compose local joint rotations along the kinematic tree.

    Args:
        rotmats: (B, J, 3, 3) local rotation of each joint relative to its parent.
        joints: (B, J, 3) rest-pose joint locations.
        parents: (J,) parent index of each joint, -1 for the root; parents[j] < j.

    Returns:
        posed_joints: (B, J, 3) joint locations after posing (root at its rest location).
        skin_transforms: (B, J, 4, 4) transforms that map a rest-pose point rigidly
            attached to joint j to its posed location (G_j · G_j(rest)^-1).
    """
    batch, num_joints = joints.shape[:2]
    rel = joints.clone()
    rel[:, 1:] = joints[:, 1:] - joints[:, parents[1:]]
    local = torch.zeros(batch, num_joints, 4, 4, dtype=joints.dtype, device=joints.device)
    local[..., :3, :3] = rotmats
    local[..., :3, 3] = rel
    local[..., 3, 3] = 1.0
    chain = [local[:, 0]]
    for j in range(1, num_joints):
        chain.append(chain[int(parents[j])] @ local[:, j])
    world = torch.stack(chain, dim=1)
    posed_joints = world[..., :3, 3]
    # Remove the rest-pose joint offset so the transform applies to rest vertices.
    offset = (world[..., :3, :3] @ joints.unsqueeze(-1)).squeeze(-1)
    skin = world.clone()
    skin[..., :3, 3] = posed_joints - offset
    return posed_joints, skin


def skin_points(points: torch.Tensor, weights: torch.Tensor, transforms: torch.Tensor) -> torch.Tensor:
    """Blend per-joint transforms by skinning weights and apply them.

    Args:
        points: (B, N, 3) rest-pose points.
        weights: (N, J) or (B, N, J) skinning weights (rows sum to 1).
        transforms: (B, J, 4, 4) per-joint skinning transforms.

    Returns:
        (B, N, 3) posed points.
    """
    if weights.dim() == 2:
        weights = weights.unsqueeze(0).expand(points.shape[0], -1, -1)
    blended = torch.einsum("bnj,bjrc->bnrc", weights, transforms[..., :3, :])
    return (blended[..., :3] @ points.unsqueeze(-1)).squeeze(-1) + blended[..., 3]


def pose_feature(rotmats: torch.Tensor) -> torch.Tensor:
    """SMPL pose-corrective feature: (R_j - I) flattened over the non-root joints.

    Args:
        rotmats: (B, J, 3, 3).

    Returns:
        (B, (J - 1) * 9).
    """
    eye = torch.eye(3, dtype=rotmats.dtype, device=rotmats.device)
    return (rotmats[:, 1:] - eye).reshape(rotmats.shape[0], -1)


def lbs(
    pose: torch.Tensor,
    v_shaped: torch.Tensor,
    joints: torch.Tensor,
    parents: torch.Tensor,
    weights: torch.Tensor,
    posedirs: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Pose a shaped rest mesh.

    Args:
        pose: (B, J, 3) axis-angle per joint.
        v_shaped: (B, V, 3) rest vertices after shape blend shapes.
        joints: (B, J, 3) rest joints.
        parents: (J,).
        weights: (V, J) skinning weights.
        posedirs: optional (P, V * 3) pose-corrective blend shapes, P = (J - 1) * 9.

    Returns:
        vertices (B, V, 3), posed joints (B, J, 3), skin transforms (B, J, 4, 4);
        no root translation applied.
    """
    rotmats = rotvec_to_rotmat(pose)
    v_posed = v_shaped
    if posedirs is not None:
        v_posed = v_shaped + (pose_feature(rotmats) @ posedirs).view_as(v_shaped)
    posed_joints, transforms = forward_kinematics(rotmats, joints, parents)
    return skin_points(v_posed, weights, transforms), posed_joints, transforms
