"""A failed pose-file load keeps the sequence loaded before and says why; the next good load
clears the error."""

from types import SimpleNamespace

import numpy as np
from pose_file_cases import amass_file

from texvocab_viewer.panels.pose import PoseSequence, load_sequence
from texvocab_viewer.status import StatusLine


def test_a_bad_path_after_a_good_sequence_keeps_it(tmp_path, monkeypatch):
    import texvocab_viewer.panels.pose as pose_panel

    shown = []
    monkeypatch.setattr(pose_panel, "_show_frame", lambda v: shown.append(v.sequence.path))
    amass_file(tmp_path / "walk.npz", frames=6)
    viewer = SimpleNamespace(
        data=SimpleNamespace(capture=None),
        sequence=None,
        sequence_error="",
        sequence_path="",
        status=StatusLine(),
        open_sequence=False,
        sequence_root="floor",
    )
    load_sequence(viewer, str(tmp_path / "walk.npz"))
    good = viewer.sequence
    assert isinstance(good, PoseSequence) and len(good.poses) == 6 and viewer.sequence_error == ""
    load_sequence(viewer, str(tmp_path / "nope.npz"))
    assert viewer.sequence is good and "nope.npz" in viewer.sequence_error
    assert viewer.status.error and viewer.status.text.startswith("pose file not loaded (kept walk.npz): ")
    assert viewer.sequence_error in viewer.status.text and viewer.open_sequence
    (tmp_path / "text.npz").write_text("not a zip")
    load_sequence(viewer, str(tmp_path / "text.npz"))
    assert viewer.sequence is good and "text.npz" in viewer.sequence_error
    amass_file(tmp_path / "walk2.npz", frames=3)
    load_sequence(viewer, str(tmp_path / "walk2.npz"))
    assert len(viewer.sequence.poses) == 3 and viewer.sequence_error == ""
    assert viewer.status.text == "loaded walk2.npz: 3 frames" and not viewer.status.error
    assert shown == [str(tmp_path / "walk.npz"), str(tmp_path / "walk2.npz")]
    assert np.isfinite(viewer.sequence.poses).all()
