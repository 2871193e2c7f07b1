"""Cloth that slides with pose: nothing moves at 0 or at the rest pose, each slide stays
on its own part's cloth with the stated size, and synth records it so the ground truth
renders it again."""

import json

import numpy as np
import pytest

from texvocab.body import default_body
from texvocab.body.poses import J
from texvocab.capture.cloth_slide import slide_offsets
from texvocab.capture.garment import Garment, regions
from texvocab.capture.motion import make_sequence
from texvocab.capture.synth import SynthRenderer, SynthSettings, settings_of, synthesize
from texvocab.cli.main import main as cli

TINY = SynthSettings(ring_views=2, raised_views=0, size=64, texture_size=128)


@pytest.fixture(scope="module")
def garment():
    return Garment(default_body(), 128)


def _offsets(garment, pose, metres=0.04):
    region = regions(garment.points, garment.weights, garment.joints)
    return region, slide_offsets(garment.points, region, garment.joints, pose, metres)


def test_nothing_slides_at_zero_or_at_rest(garment):
    bent = np.zeros((24, 3))
    bent[J["left_knee"]] = [1.4, 0, 0]
    assert garment.albedo_at(bent, 0.0) is garment.albedo
    _, off = _offsets(garment, np.zeros((24, 3)))
    assert np.abs(off).max() == 0
    np.testing.assert_array_equal(garment.albedo_at(np.zeros((24, 3)), 0.04), garment.albedo)


@pytest.mark.parametrize(
    "joint, axis, part",
    [("left_elbow", 1, "left sleeve"), ("right_knee", 0, "right leg"), ("spine2", 0, "torso")],
)
def test_each_slide_stays_on_its_own_part(garment, joint, axis, part):
    pose = np.zeros((24, 3))
    pose[J[joint], axis] = 1.2
    region, off = _offsets(garment, pose)
    moved = np.linalg.norm(off, axis=1) > 1e-6
    x = garment.points[:, 0]
    shoulder_x = abs(garment.joints[J["left_shoulder"], 0])
    own = {
        "left sleeve": (region == 2) & (x > shoulder_x),
        "right leg": (region == 3) & (x < 0),
        "torso": (region == 2) & (np.abs(x) <= shoulder_x),
    }[part]
    assert moved.any() and not (moved & ~own).any()
    size = np.linalg.norm(off, axis=1)
    # the bend's strength is 1.2 rad / 90 deg = 0.76; the free end slides the most
    assert 0.02 < size.max() <= 0.04 * 1.2 + 1e-9
    if part == "left sleeve":
        cuff = own & (x > garment.joints[J["left_wrist"], 0] - 0.05)
        seam = own & (x < shoulder_x + 0.03)
        assert size[cuff].mean() > 4 * size[seam].mean()
    albedo = garment.albedo_at(pose, 0.04)
    changed = np.abs(albedo - garment.albedo).max(-1) > 0
    assert changed.mean() > 0.002  # the pattern moved somewhere


def test_synth_records_the_slide_and_the_truth_renders_it(tmp_path):
    body = default_body()
    poses, trans = make_sequence([("squat", 2)], seed=0)
    s = SynthSettings(**{**TINY.__dict__, "cloth_slide": 0.05})
    cap = synthesize(tmp_path / "cap", poses, trans, 1, body, s, progress=False)
    meta = json.loads((cap / "texvocab_synth.json").read_text())
    assert meta["settings"]["cloth_slide"] == 0.05
    again, cams = settings_of(meta)
    assert again == s
    squat = poses[-1]
    renderer = SynthRenderer(body, again)
    ((slid, mask),) = renderer.render(squat, trans[-1], cams[:1])
    ((rest, _),) = renderer.render(squat, trans[-1], cams[:1], texture_pose=np.zeros_like(squat))
    renderer.close()
    plain = SynthRenderer(body, TINY)
    ((still, _),) = plain.render(squat, trans[-1], cams[:1], texture_pose=np.zeros_like(squat))
    plain.close()
    np.testing.assert_array_equal(rest, still)  # rest pose: neither folds nor slide
    assert np.abs(slid - rest)[mask].mean() > 0.01


def test_command_line_sets_the_slide_and_refuses_one_out_of_range(tmp_path, capsys):
    small = ["--frames", "2", "--size", "32", "--ring-views", "1", "--raised-views", "0"]
    assert cli(["synth", str(tmp_path / "ok"), "--cloth-slide", "0.05", *small, "--texture-size", "64"]) == 0
    meta = json.loads((tmp_path / "ok" / "texvocab_synth.json").read_text())
    assert meta["settings"]["cloth_slide"] == 0.05
    capsys.readouterr()
    assert cli(["synth", str(tmp_path / "cap"), "--cloth-slide", "0.5", "--frames", "1"]) != 0
    err = capsys.readouterr().err
    assert "error: --cloth-slide 0.5" in err and not (tmp_path / "cap").exists()
