"""Imperfect fits and camera imperfections: the recorded fit is the truth plus the
stated noise, readers return the recorded one, images show the truth."""

import json
import re
from pathlib import Path

import numpy as np
import pytest
import torch

from texvocab.body import default_body
from texvocab.capture import SYNTH_META
from texvocab.capture import open as open_capture
from texvocab.capture.motion import make_sequence
from texvocab.capture.synth import SynthSettings, synthesize
from texvocab.capture.synth_realism import CameraEffects, noisy_fit, rotation_error_deg

ROOT = Path(__file__).resolve().parents[2]
TINY = dict(ring_views=2, raised_views=0, size=48, texture_size=128)


@pytest.fixture(scope="module")
def body():
    return default_body()


@pytest.fixture(scope="module")
def motion():
    return make_sequence([("walk", 3), ("squat", 2)], seed=4)


@pytest.fixture(scope="module")
def pair(tmp_path_factory, body, motion):
    root = tmp_path_factory.mktemp("realism")
    clean = synthesize(root / "clean", *motion, 3, body, SynthSettings(**TINY), progress=False)
    noisy_settings = SynthSettings(**TINY, fit_noise_deg=3.0, fit_noise_trans=0.015)
    noisy = synthesize(root / "noisy", *motion, 3, body, noisy_settings, progress=False)
    return clean, noisy


def test_noise_has_the_stated_size():
    rng = np.random.default_rng(0)
    poses = rng.normal(0, 0.5, (400, 24, 3)).astype(np.float32)
    trans = rng.normal(0, 1, (400, 3)).astype(np.float32)
    rec, rec_trans = noisy_fit(poses, trans, 3.0, 0.015, seed=7)
    err = rotation_error_deg(rec, poses)
    assert abs(np.sqrt((err**2).mean()) - 3.0) < 0.1 and err.max() < 12
    dt = np.linalg.norm(rec_trans - trans, axis=1)
    assert abs(np.sqrt((dt**2).mean()) - 0.015) < 0.001
    again = noisy_fit(poses, trans, 3.0, 0.015, seed=7)[0]
    np.testing.assert_array_equal(rec, again)  # reproducible from the seed


def test_capture_records_the_noisy_fit_and_keeps_the_truth_aside(pair, body, motion):
    clean, noisy = pair
    poses, trans = motion
    cap = open_capture(noisy, body=body)
    meta = json.loads((noisy / SYNTH_META).read_text())
    true_poses = np.asarray(meta["true_poses"]).reshape(-1, 24, 3)
    np.testing.assert_allclose(true_poses, poses, atol=1e-6)
    np.testing.assert_allclose(np.asarray(meta["true_trans"]), trans, atol=1e-6)
    err = rotation_error_deg(cap.poses, poses)  # what training reads vs the truth
    assert 1.5 < np.sqrt((err**2).mean()) < 4.5
    dt = np.linalg.norm(cap.trans - trans, axis=1)
    assert 0.003 < np.sqrt((dt**2).mean()) < 0.03
    # every frame's recorded body is the noisy one
    ref = body.forward(torch.as_tensor(cap.poses[1])[None], torch.as_tensor(cap.trans[1])[None])
    np.testing.assert_allclose(cap.posed_body(1).vertices.numpy(), ref.vertices.numpy(), atol=1e-5)
    # the images show the truth: the same as the noise-free capture's
    ref_cap = open_capture(clean, body=body)
    np.testing.assert_allclose(ref_cap.poses, poses, atol=1e-5)
    for t in range(len(poses)):
        np.testing.assert_array_equal(cap.image(1, t), ref_cap.image(1, t))
    assert "true_poses" not in json.loads((clean / SYNTH_META).read_text())


def test_no_reader_or_training_code_reads_the_true_poses():
    pattern = re.compile(r"true_(poses|trans)")
    users = {
        p.relative_to(ROOT).as_posix()
        for p in (ROOT / "texvocab").rglob("*.py")
        if pattern.search(p.read_text())
    }
    assert users == {"texvocab/capture/synth.py", "texvocab/capture/synth_realism.py"}


def test_camera_effects_gain_per_camera_and_noise(tmp_path, body, motion, pair):
    clean, _ = pair
    s = SynthSettings(**TINY, exposure_sd=0.3, white_balance_sd=0.1)
    out = synthesize(tmp_path / "gains", *motion, 3, body, s, progress=False)
    cap, ref = open_capture(out, body=body), open_capture(clean, body=body)
    gains = np.asarray(cap.synthetic["camera_effects"]["gains"])
    assert gains.shape == (2, 3) and not np.allclose(gains, 1.0)
    for v in range(2):
        img, truth = cap.image(v, 4), ref.image(v, 4)
        ok = cap.mask(v, 4) & (truth.max(-1) > 0.1) & (truth.max(-1) * gains[v].max() < 0.95)
        ratio = np.median(img[ok] / np.maximum(truth[ok], 1e-3), axis=0)
        np.testing.assert_allclose(ratio, gains[v], rtol=0.05)
    effects = CameraEffects(1, 0.0, 0.0, 0.02, seed=0)
    grey = np.full((64, 64, 3), 0.5, np.float32)
    assert abs(np.std(effects.apply(0, grey) - grey) - 0.02) < 0.002
    assert not CameraEffects(3, 0.0, 0.0, 0.0, seed=0).active


def test_command_line_sets_garment_and_noise(tmp_path):
    from texvocab.cli.main import main

    out = tmp_path / "cli"
    argv = ["synth", str(out), "--garment", "wide-trousers", "--frames", "2", "--size", "32"]
    argv += ["--texture-size", "64", "--ring-views", "1", "--raised-views", "0", "--fit-noise-deg", "2"]
    assert main(argv + ["--sensor-noise", "0.01"]) == 0
    meta = json.loads((out / SYNTH_META).read_text())
    assert meta["settings"]["garment"] == "wide-trousers" and meta["settings"]["fit_noise_deg"] == 2.0
    assert meta["camera_effects"]["sensor_noise"] == 0.01 and "true_poses" in meta
    assert main(["synth", str(tmp_path / "bad"), "--garment", "tutu"]) != 0
    assert main(["synth", str(tmp_path / "bad"), "--fit-noise-deg", "-1"]) != 0
