"""Fitting the default body to a subject's rest joints: the joints are reached exactly,
the surface follows them smoothly (limbs longer along their bones, not thicker), skinning,
faces and UVs are kept, and the fitted body poses like any other."""

import logging

import numpy as np
import pytest
import torch

from texvocab.body import JOINT_NAMES, BodyModel, default_body
from texvocab.body.fit import betas_from_rest_joints, bone_changes, fit_rest_joints, refit_regressor
from texvocab.body.poses import preset
from texvocab.body.smpl_io import parents_from_kintree
from texvocab.errors import AssetError

J = {name: i for i, name in enumerate(JOINT_NAMES)}
# bone (named by its child joint) -> length factor; the trunk and hips are left as they are
STRETCH = {
    "left_knee": 1.15,
    "right_ankle": 0.9,
    "left_elbow": 1.1,
    "right_wrist": 0.92,
    "head": 0.95,
    "left_foot": 1.05,
}


@pytest.fixture(scope="module")
def body():
    return default_body()


def stretched(joints: np.ndarray, parents: np.ndarray, factors: dict[str, float]) -> np.ndarray:
    """Rest joints (J, 3) with the named bones scaled, their descendants carried along."""
    out = joints.copy()
    for j in range(1, len(parents)):
        p = parents[j]
        out[j] = out[p] + factors.get(JOINT_NAMES[j], 1.0) * (joints[j] - joints[p])
    return out


@pytest.fixture(scope="module")
def target(body):
    return stretched(body.rest_joints.double().numpy(), body.parents.numpy(), STRETCH)


@pytest.fixture(scope="module")
def fitted(body, target):
    return fit_rest_joints(body, target, source="a stretched skeleton")


def joint_error(model: BodyModel, target: np.ndarray) -> float:
    return float(np.linalg.norm(model.rest_joints.double().numpy() - target, axis=1).max())


def face_normals(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def test_fit_reaches_the_target_joints(body, target, fitted):
    assert joint_error(body, target) > 0.05  # the stretched hand is far off before
    assert joint_error(fitted, target) < 1e-6
    assert fitted.name == "default body fitted to a stretched skeleton"


def test_fitting_to_its_own_joints_is_the_identity(body):
    same = fit_rest_joints(body, body.rest_joints.numpy())
    assert torch.equal(same.v_template, body.v_template)
    assert torch.equal(same.rest_joints, body.rest_joints)


def test_surface_stays_smooth(body, fitted):
    f = body.faces.numpy()
    v0, v1 = body.v_template.double().numpy(), fitted.v_template.double().numpy()
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    ratio = np.linalg.norm(v1[edges[:, 0]] - v1[edges[:, 1]], axis=1) / np.linalg.norm(
        v0[edges[:, 0]] - v0[edges[:, 1]], axis=1
    )
    # bones change by 0.9..1.15: edges along them as much, blends between regions a little
    # more (measured: 1.2 % outside, extremes 0.84 and 1.48 on 5 mm edges at the hip)
    within = (ratio > 0.9 - 1e-6) & (ratio < 1.15 + 1e-6)
    assert within.mean() > 0.98 and 0.8 < ratio.min() and ratio.max() < 1.6
    turn = (face_normals(v0, f) * face_normals(v1, f)).sum(1)
    assert turn.min() > np.cos(np.radians(30))  # no face flips (measured: at most 22°)
    assert np.abs(v1 - v0).max() > 0.05  # the surface did move (the stretched arm)


def test_a_limb_gets_longer_along_its_bone_not_thicker(body, target, fitted):
    hip, knee = J["left_hip"], J["left_knee"]
    j0 = body.rest_joints.double().numpy()
    bone = j0[knee] - j0[hip]
    thigh = np.nonzero(body.weights[:, hip].numpy() > 0.999)[0]
    v0 = body.v_template.double().numpy()[thigh] - j0[hip]
    v1 = fitted.v_template.double().numpy()[thigh] - target[hip]
    tau = v0 @ bone / (bone @ bone)
    inside = (tau > 0) & (tau < 1)
    assert inside.sum() > 50
    axis = bone / np.linalg.norm(bone)
    along0, along1 = v0[inside] @ axis, v1[inside] @ axis
    np.testing.assert_allclose(along1, STRETCH["left_knee"] * along0, atol=1e-5)
    radial0 = v0[inside] - along0[:, None] * axis
    radial1 = v1[inside] - along1[:, None] * axis
    np.testing.assert_allclose(radial1, radial0, atol=1e-5)  # cross sections unchanged


def test_skinning_faces_and_uvs_are_kept(body, fitted):
    assert torch.equal(fitted.weights, body.weights)
    assert torch.equal(fitted.faces, body.faces) and torch.equal(fitted.parents, body.parents)
    assert torch.equal(fitted.vt, body.vt) and torch.equal(fitted.ft, body.ft)
    assert fitted.J_regressor is None and fitted.shapedirs is None


def test_the_fitted_body_poses_with_lbs(body, target, fitted):
    pose = torch.as_tensor(np.stack([preset("walk")[0], preset("arms_down")[0]]))
    trans = torch.tensor([[0.0, 0.9, 0.0], [0.3, 0.0, -1.0]])
    out = fitted.forward(pose, trans)
    assert torch.isfinite(out.vertices).all()
    # posed joints are forward kinematics of the target skeleton, whatever the surface
    bones_only = BodyModel(body.v_template, body.faces, body.weights, body.parents, joints=target)
    np.testing.assert_allclose(out.joints.numpy(), bones_only.forward(pose, trans).joints.numpy(), atol=1e-5)
    # a vertex skinned to one joint only keeps its distance to that joint
    elbow = J["left_elbow"]
    rigid = np.nonzero(body.weights[:, elbow].numpy() > 0.999)[0]
    rest = (fitted.v_template[rigid] - fitted.rest_joints[elbow]).norm(dim=-1)
    posed = (out.vertices[:, rigid] - out.joints[:, elbow, None]).norm(dim=-1)
    np.testing.assert_allclose(posed.numpy(), rest.expand_as(posed).numpy(), atol=1e-5)


def test_the_log_line_names_the_largest_bone_change(body, target, caplog):
    with caplog.at_level(logging.INFO, logger="texvocab"):
        fit_rest_joints(body, target)
    line = caplog.records[-1].getMessage()
    change = bone_changes(body.rest_joints.double().numpy(), target, body.parents.numpy())
    assert np.abs(change).argmax() == J["left_knee"]
    assert line.startswith("body: default body fitted to the capture's rest joints")
    assert f"largest bone change {100 * change[J['left_knee']]:+.1f} cm at left_knee" in line


def toy_body(a: dict) -> BodyModel:
    return BodyModel(
        a["v_template"],
        a["f"],
        a["weights"],
        parents_from_kintree(a["kintree_table"]),
        J_regressor=a["J_regressor"],
        shapedirs=a["shapedirs"],
        posedirs=a["posedirs"],
        name="toy",
        dtype=torch.float64,
    )


def test_a_joint_regressor_regresses_the_target_from_the_fitted_template(toy_arrays):
    toy = toy_body(toy_arrays)
    target = stretched(toy.rest_joints.numpy(), toy.parents.numpy(), STRETCH)
    fitted = fit_rest_joints(toy, target)
    reg = fitted.J_regressor.numpy()
    np.testing.assert_allclose(reg @ fitted.v_template.numpy(), target, atol=1e-9)
    np.testing.assert_allclose(reg.sum(1), toy.J_regressor.numpy().sum(1), atol=1e-12)
    assert not np.any(reg[toy.J_regressor.numpy() == 0])  # each row keeps its vertices
    # the shape space still moves the joints through the regressor
    betas = torch.full((1, 10), 0.5, dtype=torch.float64)
    v, joints = fitted.shaped(betas, 1)
    np.testing.assert_allclose(joints[0].numpy(), reg @ v[0].numpy(), atol=1e-9)
    assert torch.equal(fitted.posedirs, toy.posedirs) and torch.equal(fitted.shapedirs, toy.shapedirs)
    out = fitted.forward(torch.as_tensor(preset("walk")[0])[None].double(), betas=betas)
    assert torch.isfinite(out.vertices).all()


def test_betas_are_recovered_from_rest_joints_of_the_same_model(toy_arrays):
    toy = toy_body(toy_arrays)
    truth = torch.linspace(-1.5, 2.0, 10, dtype=torch.float64)[None]
    _, joints = toy.shaped(truth, 1)
    betas, error = betas_from_rest_joints(toy, joints[0].numpy())
    np.testing.assert_allclose(betas, truth[0].numpy(), atol=1e-8)
    assert error < 1e-10
    _, error = betas_from_rest_joints(toy, stretched(joints[0].numpy(), toy.parents.numpy(), STRETCH))
    assert error > 1e-3  # a skeleton outside the shape space is reported as such


def test_betas_need_a_shape_space(body):
    with pytest.raises(AssetError, match="default body has no joint regressor and shape space"):
        betas_from_rest_joints(body, body.rest_joints.numpy())


def test_a_regressor_row_that_cannot_reach_its_joint_spreads_over_all_vertices():
    verts = np.random.default_rng(0).normal(size=(20, 3))
    reg = np.zeros((1, 20))
    reg[0, :2] = 0.5  # two vertices regress only points on their line
    out = refit_regressor(reg, verts, np.array([[0.3, -0.2, 0.1]]))
    np.testing.assert_allclose(out @ verts, [[0.3, -0.2, 0.1]], atol=1e-9)
    assert np.count_nonzero(out) > 2


@pytest.mark.parametrize(
    "joints, message",
    [
        (np.zeros((23, 3)), r"rest joints have shape \(23, 3\), expected \(24, 3\)"),
        (np.full((24, 3), np.nan), "rest joints are not finite"),
    ],
)
def test_bad_rest_joints_are_refused(body, joints, message):
    with pytest.raises(AssetError, match=message):
        fit_rest_joints(body, joints, source="mesh_infos.pkl")


def test_a_collapsed_bone_is_refused(body):
    joints = body.rest_joints.double().numpy().copy()
    joints[J["left_elbow"]] = joints[J["left_shoulder"]]
    with pytest.raises(AssetError, match=r"mesh_infos.pkl: the bone to joint 18 \(left_elbow\)"):
        fit_rest_joints(body, joints, source="mesh_infos.pkl")
