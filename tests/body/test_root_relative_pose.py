"""The root-relative pose condition: blind to which way the body faces, the rest of the
pose untouched, at every root orientation, batch shape and dtype."""

import numpy as np
import pytest
import torch

from texvocab.body.pose_condition import (
    POSE_CONDITIONS,
    condition_pose,
    ignored_joints,
    root_relative_pose,
)
from texvocab.geometry.rotations import quat_multiply, quat_to_rotvec, rotvec_to_quat


def turned(pose: torch.Tensor, rotvec) -> torch.Tensor:
    """The pose with its root rotated by ``rotvec`` in the world: R0' = R · R0."""
    out = pose.clone()
    out[..., 0, :] = quat_to_rotvec(
        quat_multiply(
            rotvec_to_quat(torch.as_tensor(rotvec, dtype=pose.dtype)), rotvec_to_quat(pose[..., 0, :])
        )
    )
    return out


def random_pose(seed: int, batch=(), scale: float = 0.4) -> torch.Tensor:
    return torch.as_tensor(np.random.default_rng(seed).normal(0, scale, (*batch, 24, 3)))


# headings about the world's up axis y (±180° included) and root orientations of every kind:
# tilts, lying down, upside down (no heading is defined there), turns of 2π and beyond
TURNS = [(0, a, 0) for a in np.radians([0.0, 1e-7, 37.0, 143.0, 179.999, 180.0, -180.0, -90.0, 359.0])]
TURNS += [
    (np.pi, 0, 0),
    (0, 0, np.pi),
    (np.pi / 2, 0, 0),
    (np.pi / np.sqrt(2), 0, np.pi / np.sqrt(2)),
    (0, 2 * np.pi, 0),
    (1.3, -2.1, 0.4),
    (0, 4 * np.pi - 1e-3, 0),
]


@pytest.mark.parametrize("turn", TURNS)
def test_any_root_orientation_gives_the_same_condition(turn):
    pose = random_pose(0)
    pose[0] = torch.tensor([0.3, -2.0, 0.5], dtype=torch.float64)
    a, b = root_relative_pose(pose), root_relative_pose(turned(pose, turn))
    assert torch.equal(a, b)
    # the global pose does see the turn (a turn of 2π is the identity rotation)
    if np.linalg.norm(turn) % (2 * np.pi) > 1e-3:
        qa, qb = rotvec_to_quat(pose[0]), rotvec_to_quat(turned(pose, turn)[0])
        assert 1 - abs(float((qa * qb).sum())) > 1e-12


def test_joints_below_the_root_are_bit_for_bit_the_input():
    pose = random_pose(1, scale=2.0)
    out = root_relative_pose(pose)
    assert torch.equal(out[1:], pose[1:])
    assert torch.equal(out[0], torch.zeros(3, dtype=pose.dtype))
    zero_root = pose.clone()
    zero_root[0] = 0.0  # a body that already faces the canonical way: unchanged
    assert torch.equal(root_relative_pose(zero_root), zero_root)


@pytest.mark.parametrize("batch", [(), (1,), (5,), (2, 3), (0,)])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_batched_shapes_and_dtypes(batch, dtype):
    pose = random_pose(2, batch).to(dtype)
    out = root_relative_pose(pose)
    assert out.shape == pose.shape and out.dtype == dtype
    assert torch.equal(out[..., 1:, :], pose[..., 1:, :])
    assert not out[..., 0, :].any()
    per_frame = [root_relative_pose(p) for p in pose.reshape(-1, 24, 3)]
    if per_frame:
        assert torch.equal(torch.stack(per_frame).reshape(pose.shape), out)


def test_numpy_input():
    pose = random_pose(3).numpy()
    out = root_relative_pose(pose)
    assert isinstance(out, torch.Tensor) and out.dtype == torch.float64
    np.testing.assert_array_equal(out[1:].numpy(), pose[1:])


def test_gradients_reach_the_joints_below_the_root_only():
    pose = random_pose(4).requires_grad_(True)
    weights = torch.arange(72, dtype=torch.float64).reshape(24, 3)
    (grad,) = torch.autograd.grad((root_relative_pose(pose) * weights).sum(), pose)
    assert torch.equal(grad[1:], weights[1:]) and torch.equal(grad[0], torch.zeros(3).double())


def test_global_is_the_pose_itself_and_bad_input_is_refused():
    pose = random_pose(5)
    assert condition_pose(pose, "global") is pose
    assert torch.equal(condition_pose(pose, "root-relative"), root_relative_pose(pose))
    assert POSE_CONDITIONS[0] == "root-relative"
    assert ignored_joints("root-relative") == (0,) and ignored_joints("global") == ()
    with pytest.raises(
        ValueError, match="unknown pose condition 'facing'; expected one of root-relative, global"
    ):
        condition_pose(pose, "facing")
    with pytest.raises(ValueError, match=r"expected shape \(..., 24, 3\), got \(23, 3\)"):
        root_relative_pose(pose[1:])
    with pytest.raises(ValueError, match=r"got \(72,\)"):
        root_relative_pose(pose.reshape(72))
