"""--other-capture: eval, render, shot, view and train --resume take a checkpoint on a
capture it was not trained on when asked, with one warning line saying what differs."""

import logging
import shutil
import subprocess

import pytest
from bad_capture_cases import _copy
from other_captures import moved_camera
from train_cases import TEXVOCAB, set_arguments, tiny_settings

from texvocab.cli.main import build_parser, main
from texvocab.errors import TexvocabError
from texvocab.io.checkpoint import load_checkpoint
from texvocab_viewer.state import load_viewer_data


def _warning_lines(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if "trained on another capture" in ln]


def test_eval_on_another_capture_warns_once_and_evaluates(world, tmp_path):
    moved = _copy(world, "moved", moved_camera)
    ckpt = str(world / "run" / "checkpoint.pt")
    args = ["eval", ckpt, moved, "--per-set", "1", "--out", str(tmp_path / "eval")]
    proc = subprocess.run([TEXVOCAB, *args, "--other-capture"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    (line,) = _warning_lines(proc.stderr)
    assert line.startswith("warning: ") and "calibration differs" in line and moved in line
    assert (tmp_path / "eval" / "metrics.md").is_file()


def test_render_on_another_capture_with_the_flag(world, tmp_path, caplog):
    import numpy as np

    poses = tmp_path / "still.npz"
    np.savez(poses, poses=np.zeros((1, 72)))
    moved = _copy(world, "moved", moved_camera)
    argv = ["render", str(world / "run" / "checkpoint.pt"), "--poses", str(poses), "--capture", moved]
    caplog.set_level(logging.WARNING, logger="texvocab")
    assert main(argv + ["--out", str(tmp_path / "frames"), "--other-capture"]) == 0
    assert len(_warning_lines(caplog.text)) == 1
    assert list((tmp_path / "frames").glob("*.png"))


def test_resume_on_another_capture_with_the_flag(world, tmp_path, caplog):
    run = tmp_path / "run"
    shutil.copytree(world / "run", run)
    moved = _copy(world, "moved", moved_camera)
    sets = set_arguments(tiny_settings(iterations=2, perceptual="off"))
    argv = ["train", moved, "--out", str(run), "--resume", *sets, "--iterations", "3"]
    caplog.set_level(logging.WARNING, logger="texvocab")
    assert main(argv + ["--other-capture"]) == 0
    assert len(_warning_lines(caplog.text)) == 1
    assert load_checkpoint(run / "checkpoint.pt")["step"] == 3


def test_shot_on_another_capture_with_the_flag(world, tmp_path, caplog, capsys):
    moved = _copy(world, "moved", moved_camera)
    argv = ["shot", str(world / "run" / "checkpoint.pt"), "--capture", moved, "--camera", "1"]
    argv += ["--size", "64x64", "--out", str(tmp_path / "shot")]
    assert main(argv) == 2  # refused without the flag
    assert "calibration differs); pass --other-capture" in capsys.readouterr().err
    caplog.set_level(logging.WARNING, logger="texvocab")
    assert main(argv + ["--other-capture"]) == 0
    assert len(_warning_lines(caplog.text)) == 1
    assert (tmp_path / "shot" / "neural.png").is_file()


def test_view_takes_the_flag(world, caplog):
    moved = _copy(world, "moved", moved_camera)
    ckpt = str(world / "run" / "checkpoint.pt")
    args = build_parser().parse_args(["view", ckpt, "--capture", moved, "--other-capture"])
    assert args.other_capture is True
    with pytest.raises(TexvocabError, match="calibration differs"):
        load_viewer_data(ckpt, capture=moved)
    caplog.set_level(logging.WARNING, logger="texvocab")
    data = load_viewer_data(ckpt, capture=moved, other_capture=True)
    assert str(data.capture.root) == moved and len(_warning_lines(caplog.text)) == 1
