"""THUman4.0's fits are SMPL-X: their betas never enter SMPL's shape space; with the user's
SMPL-X model file (a stand-in the test writes in the official key layout) they give the
subject's rest joints, the body is fitted to them and SMPL-X's pelvis stays where
``transl`` puts it; without one the body keeps its shape. One log line says which."""

import logging

import numpy as np
import pytest

from texvocab.body import default_body
from texvocab.body.smplx_joints import smplx_rest_joints
from texvocab.capture import open as open_capture
from texvocab.capture.motion import make_sequence
from texvocab.capture.synth import SynthSettings, synthesize
from texvocab.errors import AssetError


@pytest.fixture(scope="module")
def body():
    return default_body()


@pytest.fixture(scope="module")
def thuman(tmp_path_factory, body):
    poses, trans = make_sequence([("walk", 2)], seed=2)
    root = synthesize(
        tmp_path_factory.mktemp("thuman") / "cap",
        poses,
        trans,
        num_train=1,
        body=body,
        settings=SynthSettings(ring_views=2, raised_views=0, size=48, texture_size=64),
        layout="thuman",
        progress=False,
    )
    params = dict(np.load(root / "smpl_params.npz"))
    params["betas"] = np.array([[1.0] + [0.0] * 9], np.float32)
    np.savez(root / "smpl_params.npz", **params)
    return root


def smplx_standin(path, rest_joints, joints=55):
    """An SMPL-X model file in the official key layout: each joint regressed from one vertex;
    beta 0 makes the subject 10 % taller about the pelvis. Returns the joints at beta 0 = 1."""
    rng = np.random.default_rng(0)
    num_v = 300
    v = rng.normal(0, 0.3, (num_v, 3))
    target = np.zeros((joints, 3))
    target[:24] = rest_joints
    target[24:] = rest_joints[20] + rng.normal(0, 0.05, (joints - 24, 3))
    v[:joints] = target
    dirs = np.zeros((num_v, 3, 20))
    dirs[:, :, 0] = 0.1 * (v - target[0])  # beta 0 = 1: 10 % larger about the pelvis
    reg = np.zeros((joints, num_v))
    reg[np.arange(joints), np.arange(joints)] = 1.0
    np.savez(path, v_template=v, shapedirs=dirs, J_regressor=reg, f=np.zeros((1, 3), np.int64))
    return target[0] + 1.1 * (target - target[0])


def test_smplx_betas_give_rest_joints_and_the_body_is_fitted(thuman, body, tmp_path, caplog):
    rest = body.rest_joints.double().numpy()
    expect = smplx_standin(tmp_path / "SMPLX_NEUTRAL.npz", rest)
    plain = open_capture(thuman)
    with caplog.at_level(logging.INFO, logger="texvocab"):
        cap = open_capture(thuman, smplx=tmp_path / "SMPLX_NEUTRAL.npz")
    assert cap.betas is None and plain.betas is None  # never SMPL's shape space
    hands = {22: 28, 23: 43}
    want = expect[:24].copy()
    for smpl, smplx in hands.items():
        want[smpl] = expect[smplx]
    np.testing.assert_allclose(cap.rest_joints, want, atol=1e-9)
    np.testing.assert_allclose(cap.body.rest_joints.double().numpy(), want, atol=1e-5)
    assert np.abs(plain.body.rest_joints.double().numpy() - rest).max() < 1e-9
    # SMPL-X's pelvis at its rest place plus transl, whatever the fit does to trans
    for t in range(cap.num_frames):
        pelvis = cap.posed_body(t).joints[0, 0].double().numpy()
        np.testing.assert_allclose(pelvis, want[0] + plain.trans[t], atol=1e-5)
    said = [r.getMessage() for r in caplog.records if "SMPL-X betas" in r.getMessage()]
    assert len(said) == 1 and "fitted to the rest joints" in said[0]


def test_without_a_model_file_the_body_keeps_its_shape(thuman, body, caplog, monkeypatch):
    monkeypatch.delenv("TEXVOCAB_SMPLX", raising=False)
    with caplog.at_level(logging.INFO, logger="texvocab"):
        cap = open_capture(thuman)
    assert cap.rest_joints is None and cap.betas is None
    said = [r.getMessage() for r in caplog.records if "SMPL-X betas" in r.getMessage()]
    assert len(said) == 1 and "keeps its own shape" in said[0]


def test_hand_joints_without_finger_joints_follow_the_wrists(body, tmp_path):
    rest = body.rest_joints.double().numpy()
    from texvocab.body.smplx_joints import read_smplx_model

    smplx_standin(tmp_path / "SMPLX_NEUTRAL.npz", rest, joints=24)
    out = smplx_rest_joints(read_smplx_model(tmp_path / "SMPLX_NEUTRAL.npz"), np.zeros(10), rest)
    np.testing.assert_allclose(out[22] - out[20], rest[22] - rest[20], atol=1e-9)


def test_a_bad_model_file_is_named(thuman, tmp_path):
    np.savez(tmp_path / "SMPLX_NEUTRAL.npz", v_template=np.zeros((5, 3)))
    with pytest.raises(AssetError, match="SMPLX_NEUTRAL.npz.*shapedirs"):
        open_capture(thuman, smplx=tmp_path / "SMPLX_NEUTRAL.npz")
