"""A checkpoint records its capture's identity (layout, frames, views, frame ids, a
calibration digest); loading it on another capture is refused with one line saying what
differs, or accepted with one warning line when asked (``other_capture``); checkpoints
written before the identity load as before."""

import logging

import pytest
import torch
from other_captures import capture_copy, fewer_frames, moved_camera
from tiny_runs import smallest_run

from texvocab.capture import capture as capture_module
from texvocab.capture import open as open_capture
from texvocab.capture.identity import IDENTITY_KEY, capture_identity, identity_differences
from texvocab.errors import TexvocabError
from texvocab.io.checkpoint import load_checkpoint
from texvocab.pipeline.avatar import load_avatar
from texvocab.pipeline.settings import Settings
from texvocab.pipeline.train import Trainer


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """root/cap (2 frames, 3 views), root/run/checkpoint.pt, and two other captures."""
    ckpt = smallest_run(tmp_path_factory.mktemp("identity"))
    root = ckpt.parent.parent
    capture_copy(root / "cap", root / "moved", moved_camera)
    capture_copy(root / "cap", root / "fewer", fewer_frames)
    return ckpt


def _warnings(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]


def test_checkpoint_records_the_identity_without_reading_images(run, monkeypatch):
    cap = open_capture(run.parent.parent / "cap")

    def no_reads(*a, **k):
        raise AssertionError("an image was read")

    monkeypatch.setattr(capture_module, "read_image", no_reads)
    monkeypatch.setattr(capture_module, "read_mask", no_reads)
    ident = capture_identity(cap)
    assert load_checkpoint(run)[IDENTITY_KEY] == ident
    assert (ident["layout"], ident["num_frames"], ident["num_views"]) == ("zju", 2, 3)
    assert ident["frame_ids"] == list(cap.frame_ids) and len(ident["calibration"]) == 32
    assert capture_identity(cap.scaled(0.5)) == ident  # resizing on load is not another capture


def test_differences_are_said_in_words():
    a = {"layout": "zju", "num_frames": 60, "num_views": 6, "frame_ids": [0, 1], "calibration": "x"}
    assert identity_differences(a, a) == []
    assert identity_differences(a, {**a, "num_frames": 540}) == ["540 frames, expected 60"]
    assert identity_differences(a, {**a, "calibration": "y"}) == ["calibration differs"]
    assert identity_differences(a, {**a, "num_views": 1, "calibration": "y"}) == ["1 view, expected 6"]
    assert identity_differences(a, {**a, "frame_ids": [0, 7]}) == [
        "frame ids differ (frame 1 is 7, expected 1)"
    ]
    assert identity_differences(a, {**a, "layout": "thuman"}) == ["layout thuman, expected zju"]


def test_load_avatar_checks_the_capture(run, caplog):
    root = run.parent.parent
    caplog.set_level(logging.INFO, logger="texvocab")
    assert load_avatar(run, open_capture(root / "cap"), progress=False).step == 2
    assert load_avatar(run, progress=False).step == 2  # the capture it records
    assert _warnings(caplog) == []
    for other, words in (("moved", "calibration differs"), ("fewer", "1 frame, expected 2")):
        with pytest.raises(TexvocabError) as e:
            load_avatar(run, open_capture(root / other), progress=False)
        msg = str(e.value)
        assert str(run) in msg and str(root / other) in msg and words in msg, msg
        assert "--other-capture" in msg and "\n" not in msg


def test_other_capture_is_accepted_with_one_warning_line(run, caplog):
    caplog.set_level(logging.INFO, logger="texvocab")
    other = run.parent.parent / "moved"
    avatar = load_avatar(run, open_capture(other), progress=False, other_capture=True)
    assert avatar.capture.root == other
    (line,) = _warnings(caplog)
    assert line.startswith("warning: ") and "calibration differs" in line and str(other) in line


def test_a_checkpoint_without_the_identity_loads_on_any_capture_silently(run, tmp_path, caplog):
    ck = torch.load(run, weights_only=True)
    del ck[IDENTITY_KEY]
    old = tmp_path / "old.pt"
    torch.save(ck, old)
    caplog.set_level(logging.INFO, logger="texvocab")
    cap = open_capture(run.parent.parent / "moved")
    assert load_avatar(old, cap, progress=False).step == 2
    assert _warnings(caplog) == []


def test_an_unreadable_identity_is_refused_by_name(run, tmp_path):
    ck = torch.load(run, weights_only=True)
    cap = open_capture(run.parent.parent / "cap")
    short = {**capture_identity(cap), "frame_ids": [0]}  # 2 frames, 1 id
    for junk in ({"layout": 3}, short, "zju"):
        ck[IDENTITY_KEY] = junk
        bad = tmp_path / "bad.pt"
        torch.save(ck, bad)
        with pytest.raises(TexvocabError, match=f"{IDENTITY_KEY} is not readable"):
            load_avatar(bad, cap, progress=False)


def test_resume_checks_the_capture(run, caplog):
    root = run.parent.parent
    settings = Settings.from_dict(load_checkpoint(run)["settings"]).with_overrides(["train.iterations=3"])
    trainer = Trainer(open_capture(root / "moved"), settings, run.parent, progress=False)
    with pytest.raises(TexvocabError, match="calibration differs.*--other-capture"):
        trainer.resume()
    caplog.set_level(logging.INFO, logger="texvocab")
    assert trainer.resume(other_capture=True) and trainer.step == 2
    assert len(_warnings(caplog)) == 1
