"""A checkpoint written before settings were grouped (tests/data/checkpoint_main, its
README says how) loads, renders as it rendered then, and resumes with the same settings
and the same step."""

import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from texvocab.capture import open as open_capture
from texvocab.io.checkpoint import load_checkpoint
from texvocab.pipeline.avatar import load_avatar
from texvocab.pipeline.evaluate import render_view
from texvocab.pipeline.settings import FLAT_NAMES, Settings, march_settings
from texvocab.pipeline.train import Trainer

DATA = Path(__file__).parents[1] / "data" / "checkpoint_main"


@pytest.fixture
def old_run(tmp_path):
    """A copy of the old capture and run (texture maps are cached into the capture)."""
    shutil.copytree(DATA / "capture", tmp_path / "capture")
    (tmp_path / "run").mkdir()
    shutil.copy(DATA / "checkpoint.pt", tmp_path / "run" / "checkpoint.pt")
    return tmp_path


def test_the_old_checkpoint_stores_flat_settings():
    ck = load_checkpoint(DATA / "checkpoint.pt")
    assert ck["version"] == 1 and "coarse_samples" in ck["settings"]
    assert "render" not in ck["settings"] and ck["step"] == 2


def test_flat_settings_load_value_for_value():
    flat = load_checkpoint(DATA / "checkpoint.pt")["settings"]
    s = Settings.from_dict(flat)
    dotted = s.dotted()
    for key, value in flat.items():
        if key == "field":
            assert {k: dotted[f"field.{k}"] for k in value} == value
        else:
            assert dotted[FLAT_NAMES[key]] == value, key
    # the values away from their defaults, in their groups
    assert (
        s.render.shell_width,
        s.render.early_stop_eps,
        s.train.coarse_samples,
        s.train.residual,
        s.train.shell_voxel,
        s.train.seed,
        s.vocab.encoder,
        s.data.eval_views,
    ) == (0.03, 2e-3, 6, "all", 0.02, 3, "pyramid", (1,))


def test_old_checkpoint_loads_and_renders_as_then(old_run):
    avatar = load_avatar(old_run / "run" / "checkpoint.pt", open_capture(old_run / "capture"), progress=False)
    cap = avatar.capture
    # the frame was stored before the residual rays' coarser passes, the gridless march of
    # a few rays and the misses probed across the shell: with those off, the same image;
    # with them (the defaults since), a few residual or marched rays take other mesh
    # samples and move by about 1e-3
    march = march_settings(avatar.settings)
    then = np.load(DATA / "render_frame1_view1_half.npy")
    for knobs, tolerance in (
        ({"fallback_grid_rays": 0, "residual_levels": 0, "miss_reach": "margin", "band_retries": 0}, 1e-5),
        ({}, 5e-3),
    ):
        rgb, stats = render_view(
            avatar.model, cap.poses[1], cap.trans[1], cap.cameras[1], march.replace(**knobs), 0.5
        )
        assert rgb.shape == then.shape == (64, 64, 3)
        assert np.abs(rgb - then).max() < tolerance and rgb.max() > 0.1  # the body, not an empty image
        assert stats.field_evals > 0


def test_old_checkpoint_resumes_one_step_as_then(old_run):
    ck = load_checkpoint(old_run / "run" / "checkpoint.pt")
    settings = Settings.from_dict(ck["settings"]).with_overrides(["iterations=3"])
    trainer = Trainer(open_capture(old_run / "capture"), settings, old_run / "run", progress=False)
    assert trainer.resume() and trainer.step == 2
    (log,) = trainer.run()
    # what the version that wrote the checkpoint logged for step 3 (the data's README)
    assert (log["evals"], log["banded"], log["residual"]) == (251, 42, 15)
    assert log["loss"] == pytest.approx(0.044322215, rel=1e-5)
    new = load_checkpoint(old_run / "run" / "checkpoint.pt")
    assert (
        new["version"] == 2
        and new["step"] == 3
        and set(new["settings"]) == {"data", "vocab", "field", "render", "train"}
    )
    resumed = Settings.from_dict(new["settings"])
    assert resumed == settings and resumed.dotted() == {
        **Settings.from_dict(ck["settings"]).dotted(),
        "train.iterations": 3,
    }
    assert not torch.equal(new["model"]["log_beta"], ck["model"]["log_beta"])


def test_old_stored_maps_load_back_and_new_checkpoints_leave_them_out(old_run, tmp_path):
    """Checkpoints no longer carry the texture maps (rebuilt from the capture's cache); one
    that stored them renders with those very maps."""
    ck = load_checkpoint(old_run / "run" / "checkpoint.pt")
    stored = ck["model"]["pose_feature.textures"]
    avatar = load_avatar(old_run / "run" / "checkpoint.pt", open_capture(old_run / "capture"), progress=False)
    assert torch.equal(avatar.model.pose_feature.textures, stored)
    assert "pose_feature.textures" not in avatar.model.state_dict()
