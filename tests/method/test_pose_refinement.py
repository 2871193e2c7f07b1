"""Pose refinement: the point warp is the identity at zero correction (the field is the one
without refinement) and exact for a rigid root correction; a training run on a capture
whose recorded root translation is off moves its corrections towards the truth, and
the checkpoint keeps them for --resume."""

import dataclasses

import numpy as np
import pytest
import torch
from train_cases import tiny_settings

from texvocab.body import default_body
from texvocab.capture import open as open_capture
from texvocab.geometry.rotations import rotvec_to_rotmat
from texvocab.io.checkpoint import load_checkpoint
from texvocab.method.pose_refinement import PoseRefinement
from texvocab.pipeline.model import build_model, load_textures
from texvocab.pipeline.train import Trainer


@pytest.fixture(scope="module")
def body():
    return default_body()


def test_zero_correction_leaves_the_field_unchanged(capture):
    cap = open_capture(capture)
    s = tiny_settings()
    torch.manual_seed(0)
    model = build_model(cap, s, load_textures(cap, s, progress=False))
    ctx = model.pose_feature.context(cap.poses[0], cap.trans[0])
    refine = PoseRefinement(cap.num_train, cap.body.num_joints, "joints")
    warped = dataclasses.replace(ctx, warp=refine.warp(0, cap.body, cap.poses[0], cap.trans[0]))
    pts = ctx.vertices[::50].detach() + 0.01 * torch.randn(len(ctx.vertices[::50]), 3)
    dirs = torch.nn.functional.normalize(torch.randn_like(pts), dim=-1)
    a = model.sdf_and_color(ctx, pts, dirs)
    b = model.sdf_and_color(warped, pts, dirs)
    assert torch.allclose(a[0], b[0], atol=1e-5) and torch.allclose(a[1], b[1], atol=1e-5)


def test_root_correction_warps_points_rigidly(body):
    pose = torch.zeros(24, 3)
    pose[0] = torch.tensor([0.0, 0.4, 0.0])
    trans = torch.tensor([0.1, 0.0, 0.2])
    refine = PoseRefinement(1, body.num_joints, "root")
    with torch.no_grad():
        refine.rot[0][0] = torch.tensor([0.0, 0.1, 0.0])
        refine.trans[0][:] = torch.tensor([0.02, -0.01, 0.0])
    warp = refine.warp(0, body, pose, trans)
    new_pose, new_trans = refine.refined(0, pose, trans)
    old_v = body.forward(pose[None], trans[None]).vertices[0]
    new_v = body.forward(new_pose[None].detach(), new_trans[None].detach()).vertices[0]
    skin = body.weights.float()
    x, d = warp(new_v, torch.nn.functional.normalize(new_v, dim=-1), skin)
    # the corrected body's vertex goes back onto the recorded body's same vertex
    assert (x - old_v).norm(dim=-1).max() < 1e-4
    turn = rotvec_to_rotmat(torch.tensor([0.0, 0.1, 0.0], dtype=torch.float64)).float()
    expect = torch.nn.functional.normalize(new_v, dim=-1) @ turn  # R^T d, row vectors
    assert torch.allclose(d, expect, atol=1e-5)


def test_refinement_moves_an_offset_root_towards_the_truth(capture, tmp_path):
    """The recorded translation of every training frame 3 cm off sideways and 2 cm off
    in depth: 60 steps of root refinement take every frame's error down by a third or
    more, all in the direction of the truth, and --resume gets them back."""
    cap = open_capture(capture)
    offset = np.array([0.03, 0.0, -0.02], np.float32)
    cap.trans = cap.trans.copy()
    cap.trans[: cap.num_train] += offset
    s = tiny_settings(iterations=60, pose_refinement="root", pose_lr=5e-3, checkpoint_every=30)
    trainer = Trainer(cap, s, tmp_path / "run", progress=False)
    trainer.run()
    found = trainer.refine.state()["trans"].numpy()
    before = np.linalg.norm(offset)
    after = np.linalg.norm(found + offset, axis=1)
    assert (after < 0.67 * before).all(), (found, after)
    assert (found @ -offset > 0).all()
    ck = load_checkpoint(trainer.checkpoint_path)
    assert np.allclose(ck["pose_refinement"]["trans"].numpy(), found)
    again = Trainer(cap, s, tmp_path / "run", progress=False)
    assert again.resume() and np.allclose(again.refine.state()["trans"].numpy(), found)


def test_shared_corrections_blend_between_control_frames(body):
    """span 3 over 7 frames: controls on frames 0, 3, 6; frame 4 reads 2/3 of control 1
    and 1/3 of control 2, a step on it trains exactly those two, and the state's
    per-frame rows are the blends (what the benches read)."""
    refine = PoseRefinement(7, body.num_joints, "root", span=3)
    assert len(refine.rot) == 3 and len(refine.trans) == 3
    with torch.no_grad():
        for i, p in enumerate(refine.trans):
            p[:] = torch.tensor([float(i), 0.0, 0.0])
    rot, tr = refine.delta(4)
    assert rot.shape == (body.num_joints, 3) and tr[0].item() == pytest.approx(4 / 3)
    refine.prior(4).backward()
    grads = [p.grad is not None and p.grad.abs().sum() > 0 for p in refine.trans]
    assert grads == [False, True, True]
    state = refine.state()
    assert state["trans"].shape == (7, 3) and state["control_trans"].shape == (3, 3)
    assert np.allclose(state["trans"][:, 0].numpy(), np.arange(7) / 3)
    again = PoseRefinement(7, body.num_joints, "root", span=3)
    again.load(state)
    assert torch.equal(again.state()["trans"], state["trans"])
    with pytest.raises(ValueError, match="span"):
        PoseRefinement(7, body.num_joints, "root").load(state)


def test_shared_corrections_move_an_offset_root_towards_the_truth(capture, tmp_path):
    """The same 3 cm / 2 cm offset on every training frame, corrections shared by every
    second frame: 40 steps take every frame's error down by a third or more."""
    cap = open_capture(capture)
    offset = np.array([0.03, 0.0, -0.02], np.float32)
    cap.trans = cap.trans.copy()
    cap.trans[: cap.num_train] += offset
    s = tiny_settings(iterations=40, pose_refinement="root", pose_refinement_span=2, checkpoint_every=40)
    trainer = Trainer(cap, s, tmp_path / "run", progress=False)
    trainer.run()
    assert len(trainer.refine.trans) < cap.num_train
    found = trainer.refine.state()["trans"].numpy()
    after = np.linalg.norm(found + offset, axis=1)
    assert (after < 0.67 * np.linalg.norm(offset)).all(), (found, after)
