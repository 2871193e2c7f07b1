"""texvocab eval scores a synthetic capture's fold regions beside the whole image."""

from types import SimpleNamespace

import numpy as np

from texvocab.body import default_body
from texvocab.capture import open as open_capture
from texvocab.capture.fold_regions import FoldRegions
from texvocab.capture.motion import make_sequence
from texvocab.capture.synth import SynthSettings, synthesize
from texvocab.pipeline import evaluate


def test_eval_reports_fold_region_metrics(tmp_path, monkeypatch):
    body = default_body()
    poses, trans = make_sequence([("squat", 3)], seed=0)
    s = SynthSettings(ring_views=2, raised_views=0, size=48, texture_size=128, garment="hoodie")
    out = synthesize(tmp_path / "cap", poses[1:], trans[1:], 1, body, s, progress=False)
    cap = open_capture(out, body=body)

    def fake_render(model, pose, trans, camera, march, scale=1.0):
        gt = cap.image(0 if camera.name == "view0" else 1, 1)
        return gt * 0.8, np.ones(gt.shape[:2], np.float32), SimpleNamespace(seconds=0.0)

    monkeypatch.setattr(evaluate, "render_view_rgba", fake_render)
    sets = {"novel_poses": evaluate.CaptureItems(cap, [(1, 0), (1, 1)])}
    table, records, _ = evaluate.evaluate_sets(None, sets, None, progress=False)
    row = table["novel_poses"]
    region = FoldRegions.load(out).region(1, 0)
    assert region.any() and row["fold_images"] == 2
    assert row["psnr_fold"] < row["psnr_bbox"]  # the fold pixels are the bright, clothed ones
    assert records[0]["fold_pixels"] == region.sum()
    text = evaluate.format_table(table)
    assert "psnr_fold" in text and "Fold regions" in text
    # the stand-in render is opaque everywhere: every fold pixel is drawn
    assert row["fold_empty"] == 0.0 and row["psnr_fold_drawn"] == row["psnr_fold"]
    assert "psnr_fold drawn" in text
