"""BodyModel / LBS against an independent per-vertex reference, pose validation, parts."""

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from texvocab.body.model import BodyModel
from texvocab.body.parts import BODY_PARTS, JOINT_NAMES, body_parts, part_attention
from texvocab.body.smpl_io import parents_from_kintree
from texvocab.errors import PoseError


def _model(a, **kw):
    return BodyModel(
        v_template=a["v_template"],
        faces=a["f"],
        weights=a["weights"],
        parents=parents_from_kintree(a["kintree_table"]),
        J_regressor=a["J_regressor"],
        shapedirs=a["shapedirs"],
        dtype=torch.float64,
        **kw,
    )


def _reference_lbs(v, joints, parents, weights, pose, trans):
    """Textbook LBS with scipy rotations, one joint and one vertex at a time."""
    world = []
    for j in range(len(parents)):
        local = np.eye(4)
        local[:3, :3] = Rotation.from_rotvec(pose[j]).as_matrix()
        local[:3, 3] = joints[j] - (joints[parents[j]] if parents[j] >= 0 else 0)
        world.append(local if parents[j] < 0 else world[parents[j]] @ local)
    out = np.zeros_like(v)
    for i in range(len(v)):
        acc = np.zeros(3)
        for j in range(len(parents)):
            if weights[i, j]:
                acc += weights[i, j] * (world[j][:3, :3] @ (v[i] - joints[j]) + world[j][:3, 3])
        out[i] = acc + trans
    return out, np.array([w[:3, 3] for w in world]) + trans


def test_lbs_matches_reference(toy_arrays):
    body = _model(toy_arrays)
    rng = np.random.default_rng(1)
    pose = rng.normal(0, 0.6, (24, 3))
    trans = np.array([0.1, -0.2, 0.3])
    out = body.forward(torch.tensor(pose)[None], torch.tensor(trans)[None])
    joints = toy_arrays["J_regressor"] @ toy_arrays["v_template"]
    ref_v, ref_j = _reference_lbs(
        toy_arrays["v_template"], joints, body.parents.numpy(), toy_arrays["weights"], pose, trans
    )
    np.testing.assert_allclose(out.vertices[0].numpy(), ref_v, atol=1e-10)
    np.testing.assert_allclose(out.joints[0].numpy(), ref_j, atol=1e-10)
    # transforms map rest points rigidly attached to a joint to their posed location
    T = out.transforms[0].numpy()
    np.testing.assert_allclose(T[:, :3, :3] @ joints[..., None] + T[:, :3, 3:], ref_j[..., None], atol=1e-10)


def test_zero_pose_is_rest_and_betas_move_joints(toy_arrays):
    body = _model(toy_arrays)
    zero = body.forward(torch.zeros(2, 24, 3))
    np.testing.assert_allclose(zero.vertices[1].numpy(), toy_arrays["v_template"], atol=1e-12)
    betas = torch.zeros(2, 10, dtype=torch.float64)
    betas[1, 0] = 3.0
    shaped = body.forward(torch.zeros(2, 24, 3), betas=betas)
    assert torch.allclose(shaped.vertices[0], zero.vertices[0])
    assert (shaped.joints[1] - zero.joints[1]).abs().max() > 1e-3


def test_posedirs_apply_only_when_posed(toy_arrays):
    a = toy_arrays
    plain = _model(a)
    corr = _model(a, posedirs=a["posedirs"])
    assert torch.allclose(
        plain.forward(torch.zeros(1, 24, 3)).vertices, corr.forward(torch.zeros(1, 24, 3)).vertices
    )
    pose = torch.full((1, 24, 3), 0.3, dtype=torch.float64)
    diff = (plain.forward(pose).vertices - corr.forward(pose).vertices).abs().max()
    assert diff > 1e-5


def test_gradients_are_finite_at_zero_pose(toy_arrays):
    body = _model(toy_arrays)
    pose = torch.zeros(1, 24, 3, dtype=torch.float64, requires_grad=True)
    body.forward(pose).vertices.square().sum().backward()
    assert torch.isfinite(pose.grad).all()


@pytest.mark.parametrize("joint", [0, 4, 18, 23])
def test_nan_pose_names_the_joint(toy_arrays, joint):
    body = _model(toy_arrays)
    pose = torch.zeros(1, 24, 3)
    pose[0, joint, 1] = float("nan")
    with pytest.raises(PoseError, match=rf"pose\[0, {joint}\] \({JOINT_NAMES[joint]}\) is not finite"):
        body.forward(pose)


def test_wrong_pose_shape_and_bad_trans(toy_arrays):
    body = _model(toy_arrays)
    with pytest.raises(PoseError, match=r"expected \(B, 24, 3\)"):
        body.forward(torch.zeros(1, 72))
    with pytest.raises(PoseError, match="trans is not finite"):
        body.forward(torch.zeros(1, 24, 3), torch.tensor([[0.0, float("inf"), 0.0]]))


def test_body_part_table_partitions_the_skeleton():
    joints = sorted(j for part in BODY_PARTS.values() for j in part)
    assert joints == list(range(24))  # each joint in exactly one of the 5 parts
    assert BODY_PARTS["main_body"] == (0, 1, 2, 3, 6, 9, 12, 15)
    assert len(body_parts("joint")) == 24 and len(body_parts("global")) == 1
    with pytest.raises(ValueError, match="unknown vocabulary strategy"):
        body_parts("limbs")


def test_part_attention():
    parts = list(BODY_PARTS.values())
    w = torch.zeros(3, 24)
    w[0, 18] = 1.0  # left elbow only -> all attention on the left arm
    w[1, 4], w[1, 1] = 0.25, 0.75  # knee + hip -> left leg 0.25, main body 0.75
    # row 2: all zero -> zero attention, not NaN
    att = part_attention(w, parts)
    np.testing.assert_allclose(att[0].numpy(), [0, 0, 0, 1, 0])
    np.testing.assert_allclose(att[1].numpy(), [0.75, 0.25, 0, 0, 0])
    assert torch.equal(att[2], torch.zeros(5))
    rand = torch.rand(100, 24)
    np.testing.assert_allclose(part_attention(rand, parts).sum(-1).numpy(), 1.0, rtol=1e-6)
    # Unnormalised weights are normalised (Ω divides by Σ_j ω).
    np.testing.assert_allclose(
        part_attention(rand * 7, parts).numpy(), part_attention(rand, parts).numpy(), rtol=1e-5
    )
