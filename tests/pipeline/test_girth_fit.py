"""The body's girth from the training masks (texvocab.pipeline.girth_fit): a person on the
body keeps a zero girth; masks wider than the body (the tiny capture's masks dilated, a
stand-in for clothes off the body) give it one that raises the grown silhouette's IoU; the
field's SDF starts that much outside the body; a run stores the offsets and every load of
the avatar sets them again."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from grown_masks import grown
from train_cases import tiny_settings

from texvocab.capture import open as open_capture
from texvocab.errors import TexvocabError
from texvocab.pipeline.girth_fit import CHECKPOINT_KEY, apply_stored_girth, candidate_offsets, fit_girth
from texvocab.pipeline.model import train_views
from texvocab.pipeline.settings import Settings

GIRTH = Settings().with_overrides(["data.body_girth=masks"])


def test_candidates_reach_to_the_shell_less_room():
    c = candidate_offsets(0.06)
    assert c[0] == pytest.approx(-0.02) and c[-1] == pytest.approx(0.04) and np.allclose(np.diff(c), 0.01)
    assert 0.0 in c and len(candidate_offsets(0.04)) == 5


def test_a_person_on_the_body_keeps_a_zero_girth(capture):
    cap = open_capture(capture)
    fit = fit_girth(cap, GIRTH, train_views(cap, GIRTH))
    assert fit.images == 16 and fit.iou_before > 0.9  # 4 frames x 4 training views
    assert fit.iou_after >= fit.iou_before and np.abs(fit.offsets).max() <= 0.02
    assert fit_girth(cap, Settings(), [0]) is None  # data.body_girth=none, the default


def test_masks_wider_than_the_body_give_it_a_girth(capture):
    cap = grown(capture, 1)
    fit = fit_girth(cap, GIRTH, train_views(cap, GIRTH))
    assert fit.iou_after > fit.iou_before + 0.05
    assert fit.offsets.mean() > 0.01 and fit.offsets.max() <= 0.02 + 1e-9  # 4 cm shell less 2 cm
    assert "body girth: " in fit.line() and f"{fit.iou_after:.3f}" in fit.line()


def test_the_sdf_starts_outside_the_body_by_the_girth(capture, tmp_path):
    from texvocab.io.checkpoint import load_checkpoint
    from texvocab.pipeline.avatar import load_avatar
    from texvocab.pipeline.train import Trainer

    cap = grown(capture, 1)
    s = tiny_settings(iterations=1).with_overrides(["data.body_girth=masks"])
    trainer = Trainer(cap, s, tmp_path / "run", progress=False)
    model = trainer.model
    assert np.allclose(model.girth.numpy(), trainer.girth_fit.offsets)
    # a fresh field's SDF is d_body - g: compare with the same field at zero girth
    ctx = model.pose_feature.context(torch.as_tensor(cap.poses[0]), torch.as_tensor(cap.trans[0]))
    pts = cap.posed_body(0).vertices[0, ::50] + 0.005
    dirs = torch.nn.functional.normalize(torch.ones_like(pts), dim=-1)
    with torch.no_grad():
        offset_sdf, _, valid = model.sdf_and_color(ctx, pts, dirs)
        girth = model.girth.clone()
        model.set_girth(torch.zeros_like(girth))
        plain, _, _ = model.sdf_and_color(ctx, pts, dirs)
        model.set_girth(girth)
    drop = (plain - offset_sdf)[valid]
    assert valid.sum() > 10 and float(drop.min()) >= float(girth.min()) - 1e-5
    assert float(drop.max()) <= float(girth.max()) + 1e-5 and float(drop.mean()) > 0.01
    trainer.run()
    ck = load_checkpoint(trainer.checkpoint_path)
    assert np.allclose(ck[CHECKPOINT_KEY], trainer.girth_fit.offsets, atol=1e-6)
    avatar = load_avatar(trainer.checkpoint_path, open_capture(capture))
    assert torch.allclose(avatar.model.girth, model.girth)
    with pytest.raises(TexvocabError, match=CHECKPOINT_KEY):
        apply_stored_girth(avatar.model, {CHECKPOINT_KEY: [0.01, float("nan")]}, "ck.pt")


def test_checkpoints_before_the_knob_read_as_no_girth():
    d = Settings().to_dict()
    del d["data"]["body_girth"]
    assert Settings.from_dict(d).data.body_girth == "none"
