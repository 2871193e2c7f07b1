"""Another capture than the checkpoint's for the front door's table (test_cli_bad_input.py):
eval, render and train --resume on a copy of the world's capture with a camera moved or a
frame fewer, without --other-capture. Each case is (id, argv builder, words of the error
line)."""

import numpy as np
from bad_capture_cases import _copy, _pose_file
from other_captures import fewer_frames, moved_camera


def _ckpt(world) -> str:
    return str(world / "run" / "checkpoint.pt")


def _render(world, *extra) -> list[str]:
    still = _pose_file(world, "still_identity.npz", poses=np.zeros((2, 72)))
    return ["render", _ckpt(world), "--poses", still, "--out", str(world / "x.mp4"), *extra]


def identity_cases(resume_sets: list[str]) -> list:
    """The cases; ``resume_sets``: the --set arguments that resume the world's run."""
    return [
        (
            "eval-other-capture",
            lambda w: ["eval", _ckpt(w), _copy(w, "moved", moved_camera)],
            "(calibration differs); pass --other-capture",
        ),
        (
            "eval-fewer-frames",
            lambda w: ["eval", _ckpt(w), _copy(w, "fewer", fewer_frames)],
            "(4 frames, expected 5); pass --other-capture",
        ),
        (
            "render-other-capture",
            lambda w: _render(w, "--capture", _copy(w, "moved", moved_camera)),
            "trained on another capture than",
        ),
        (
            "resume-other-capture",
            lambda w: (
                ["train", _copy(w, "moved", moved_camera), "--out", str(w / "run"), "--resume"]
                + resume_sets
                + ["--iterations", "3"]
            ),
            "calibration differs",
        ),
        (
            "train-other-capture-without-resume",
            lambda w: ["train", str(w / "cap"), "--out", str(w / "new_run"), "--other-capture"],
            "--other-capture applies with --resume",
        ),
    ]
