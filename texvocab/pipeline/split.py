"""Which views a run trains on and which it scores, for captures with one camera.

A multi-view capture holds out views (``eval_views``) and frames (the novel poses after
``num_train``). A one-camera capture (HumanNeRF layout) has no view to hold out: it
trains on its camera's training frames and holds out frames only. Its novel frames are
scored from the capture camera, and its training frames are scored too, from the very
view they trained on: a *seen view*, which every report labels as such.
"""

from __future__ import annotations

from texvocab.errors import TexvocabError

#: The one view of a one-camera capture.
CAPTURE_CAMERA = 0


def one_camera(capture) -> bool:
    """Whether the capture's split holds out frames only (it has a single view)."""
    return capture.num_views == 1


def one_camera_train_views(capture, train_views: tuple[int, ...] | None) -> list[int]:
    """The training views of a one-camera capture: its camera. A ``train_views`` setting
    naming another view is an error; ``eval_views`` is not used (no view is held out)."""
    if train_views is not None and list(train_views) != [CAPTURE_CAMERA]:
        raise TexvocabError(
            f"setting train_views={list(train_views)}: {capture.root} has one "
            f"camera (view {CAPTURE_CAMERA}); it holds out frames, not views"
        )
    return [CAPTURE_CAMERA]


def scored_views(capture, eval_views: tuple[int, ...]) -> list[int]:
    """The views evaluation renders: ``eval_views`` (held out, each must exist), or the
    capture camera of a one-camera capture."""
    if one_camera(capture):
        return [CAPTURE_CAMERA]
    views = list(eval_views)
    if any(v >= capture.num_views for v in views):
        raise TexvocabError(
            f"eval_views {views}: {capture.root} has views 0.."
            f"{capture.num_views - 1} (the checkpoint holds out views it lacks)"
        )
    return views


def split_note(capture) -> str:
    """One sentence for reports: what is held out."""
    novel = capture.num_frames - capture.num_train
    if one_camera(capture):
        return (
            f"one camera, no held-out view: novel_poses are the last {novel} of "
            f"{capture.num_frames} frames (held out), rendered from the capture camera; "
            "training_poses are training frames from the view they trained on (seen view)"
        )
    return f"held-out views; novel_poses are the last {novel} of {capture.num_frames} frames"
