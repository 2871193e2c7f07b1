"""bench/pose_signal.py: the pose-dependent signal on the whole image and, on a capture
with fold regions, on those pixels alone."""

import importlib.util
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _load():
    spec = importlib.util.spec_from_file_location("bench_pose_signal", ROOT / "bench" / "pose_signal.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_fold_regions_get_their_own_row(tmp_path, capsys):
    """The rest pose's folds differ from the truth on every fold pixel, so they score far
    lower there than over the whole box; the true folds' own pose (part-wise nearest, every
    part seen) scores higher than the rest pose's."""
    from texvocab.body import default_body
    from texvocab.capture.motion import make_sequence
    from texvocab.capture.synth import SynthSettings, synthesize

    poses, trans = make_sequence([("squat", 4)], seed=0)
    s = SynthSettings(ring_views=3, raised_views=0, size=64, texture_size=128, garment="hoodie")
    cap = synthesize(tmp_path / "cap", poses, trans, 2, default_body(), s, progress=False)
    assert _load().main([str(cap), "--views", "1", "2"]) == 0
    out = capsys.readouterr().out
    cells = {
        row.split(" | ")[0].strip("| "): [float(c) for c in re.findall(r"(-?[\d.]+) ± ", row)]
        for row in out.splitlines()
        if row.startswith("| bbox") or row.startswith("| fold")
    }
    named = [k for k in cells if k.startswith("fold regions")]
    assert len(named) == 1 and int(re.search(r"\((\d+) images\)", named[0])[1]) >= 2
    bbox, fold = cells["bbox"], cells[named[0]]
    assert len(bbox) == len(fold) == 3
    assert fold[0] < bbox[0] - 5  # rest-pose folds on the fold pixels
    assert fold[2] > fold[0]  # part-wise nearest folds beat the rest pose's there


def test_avatar_paired_with_each_column_image_by_image(tmp_path, capsys):
    """--avatar pairs a texvocab eval report with the columns by frame and view: an avatar
    at 500 dB on every image (above any column) is that far ahead of each column's own
    mean, on every image; a report without one of the capture's novel images is one error
    line and exit 1."""
    import json

    import pytest

    from texvocab.body import default_body
    from texvocab.capture import open as open_capture
    from texvocab.capture.motion import make_sequence
    from texvocab.capture.synth import SynthSettings, synthesize

    poses, trans = make_sequence([("squat", 4)], seed=0)
    s = SynthSettings(ring_views=3, raised_views=0, size=64, texture_size=128, garment="hoodie")
    cap = synthesize(tmp_path / "cap", poses, trans, 2, default_body(), s, progress=False)
    novel = list(open_capture(cap).novel_frames)
    rows = [
        {"set": "novel_poses", "frame": t, "view": v, "psnr_bbox": 500.0, "psnr_fold": 400.0}
        for t in novel
        for v in (1, 2)
    ]
    report = tmp_path / "metrics.json"
    report.write_text(json.dumps({"images": rows + [{"set": "training_poses", "frame": 0, "view": 1}]}))
    assert _load().main([str(cap), "--views", "1", "2", "--avatar", str(report)]) == 0
    out = capsys.readouterr().out

    def cells(prefix):
        return [
            [float(c) for c in re.findall(r"(-?[\d.]+) ± ", r)]
            for r in out.splitlines()
            if r.startswith(prefix)
        ]

    (column_bbox,), (paired_bbox,) = cells("| bbox |"), cells("| bbox (")
    column_fold, paired_fold = cells("| fold regions (")
    assert len(paired_bbox) == len(paired_fold) == 3
    assert all(p == pytest.approx(500 - c, abs=0.011) for p, c in zip(paired_bbox, column_bbox, strict=True))
    assert all(p == pytest.approx(400 - c, abs=0.011) for p, c in zip(paired_fold, column_fold, strict=True))
    assert out.count("(100%)") == 6
    report.write_text(json.dumps({"images": rows[1:]}))
    with pytest.raises(SystemExit, match=r"error: .*metrics.json: no novel_poses image for frame"):
        _load().main([str(cap), "--views", "1", "2", "--avatar", str(report)])
