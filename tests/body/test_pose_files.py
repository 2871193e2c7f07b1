"""Pose files as they come: AMASS SMPL-H (T, 156) and SMPL-X (T, 165) read into SMPL's 24
joints, resampled to a chosen frame rate and turned from AMASS's Z-up to +Y up, so a
person stands upright with no flag."""

import numpy as np
import pytest
import torch
from pose_file_cases import amass_file

from texvocab.body import default_body
from texvocab.body.pose_files import read_pose_sequence
from texvocab.errors import AssetError
from texvocab.geometry.rotations import rotvec_to_rotmat


def posed_joints(seq, i):
    out = default_body().forward(torch.as_tensor(seq.poses[i])[None], torch.as_tensor(seq.trans[i])[None])
    return out.joints[0].numpy()


@pytest.mark.parametrize("width,key", [(156, "mocap_framerate"), (165, "mocap_frame_rate")])
def test_amass_layouts_stand_upright_at_30_fps(tmp_path, width, key):
    raw, trans = amass_file(tmp_path / "walk.npz", width=width, rate_key=key)
    seq = read_pose_sequence(tmp_path / "walk.npz")
    assert seq.layout == ("smplh" if width == 156 else "smplx")
    assert seq.source_fps == 120 and seq.fps == 30 and len(seq) == 31  # 1 s at 30 fps
    assert np.allclose(seq.poses[:, 22:], 0)  # SMPL hands zero; fingers dropped
    # every 4th source frame, exactly (nlerp at whole frames)
    assert np.allclose(seq.poses[:, 4, 0], raw[::4, 12], atol=1e-5)
    for i in (0, 15, 30):
        j = posed_joints(seq, i)
        head, pelvis = j[15], j[0]
        assert head[1] - pelvis[1] > 0.4  # upright in +Y
        assert abs(head[0] - pelvis[0]) < 0.1 and abs(head[2] - pelvis[2]) < 0.1
    # root translation kept: the walk along +X stays along +X; height goes to +Y
    assert posed_joints(seq, 30)[0][0] - posed_joints(seq, 0)[0][0] == pytest.approx(1.0, abs=1e-3)
    assert np.allclose(rotvec_to_rotmat(seq.poses[0, 0]).numpy(), np.eye(3), atol=1e-5)


def test_z_up_turn_keeps_the_posed_body_rigidly_rotated(tmp_path):
    """The turned sequence poses the same body as the Z-up one, rotated by -90° about X
    (translation compensated about the pelvis)."""
    amass_file(tmp_path / "walk.npz")
    z_up = read_pose_sequence(tmp_path / "walk.npz", up="y")  # as stored (no turn)
    y_up = read_pose_sequence(tmp_path / "walk.npz")
    R = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])
    for i in (0, 17):
        assert np.allclose(posed_joints(z_up, i) @ R.T, posed_joints(y_up, i), atol=1e-4)


def test_root_zero_and_no_rate_keep_every_frame(tmp_path):
    amass_file(tmp_path / "walk.npz", frames=10)
    seq = read_pose_sequence(tmp_path / "walk.npz", root="zero", fps=None)
    assert len(seq) == 10 and seq.fps == 120
    assert np.allclose(seq.poses[:, 0], 0) and np.allclose(seq.trans, 0)
    np.savez(tmp_path / "smpl.npz", poses=np.zeros((5, 72)))
    plain = read_pose_sequence(tmp_path / "smpl.npz")
    assert plain.layout == "smpl" and len(plain) == 5 and plain.fps is None
    np.savez(tmp_path / "empty.npz", poses=np.zeros((0, 24, 3)))
    assert len(read_pose_sequence(tmp_path / "empty.npz")) == 0  # callers say "0 frames"


@pytest.mark.parametrize(
    "poses,extra,match",
    [
        (np.zeros((4, 100)), {}, r"'poses' has shape \(4, 100\); expected .*156.*165"),
        (np.zeros((4, 156)), {"mocap_framerate": -1.0}, "'mocap_framerate' is"),
        (np.zeros((4, 156)), {"trans": np.zeros((3, 3))}, "'trans' has shape"),
        (np.zeros(()), {}, r"'poses' has shape \(\)"),
        (np.zeros((0, 5, 3)), {}, r"'poses' has shape \(0, 5, 3\)"),
    ],
)
def test_bad_pose_files_name_the_array(tmp_path, poses, extra, match):
    np.savez(tmp_path / "bad.npz", poses=poses, **extra)
    with pytest.raises(AssetError, match=match):
        read_pose_sequence(tmp_path / "bad.npz")
