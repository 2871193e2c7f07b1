"""bench/silhouette_errors.py: each reading tells the error it is for (a shift, a fat
silhouette, a soft edge), and the bench runs on a real checkpoint."""

import sys
from pathlib import Path

import numpy as np
from tiny_runs import smallest_run

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))

import silhouette_errors  # noqa: E402


def _disk(cx, cy, r, size=64):
    ys, xs = np.mgrid[:size, :size]
    return (xs - cx) ** 2 + (ys - cy) ** 2 <= r * r


def test_a_shifted_render_is_found_at_its_shift():
    mask = _disk(30, 30, 12)
    row = silhouette_errors.silhouette_row(_disk(28, 33, 12).astype(float), mask, 5)
    assert (row["dx"], row["dy"]) == (2, -3) and row["best_shift_iou"] == 1.0 > row["iou@0.5"]


def _soft_disk(cx, cy, r, size=64, k=8):
    """Pixel coverage (size, size) of a disk, pixel centres at integers."""
    ys, xs = (np.mgrid[: size * k, : size * k] + 0.5) / k - 0.5
    inside = (xs - cx) ** 2 + (ys - cy) ** 2 <= r * r
    return inside.reshape(size, k, size, k).mean((1, 3))


def test_a_sub_pixel_shift_of_a_fat_render_is_read_from_its_outline():
    """The render 1.5 px too fat and (-0.5, +0.75) px off: the outline's sides give the
    move that puts it on the mask, which no whole-pixel shift can."""
    row = silhouette_errors.silhouette_row(_soft_disk(29.5, 30.75, 13.5), _disk(30, 30, 12), 2)
    assert abs(row["edge_dx"] - 0.5) < 0.15 and abs(row["edge_dy"] + 0.75) < 0.15


def test_a_fat_render_scores_best_against_the_dilated_mask():
    mask = _disk(30, 30, 12)
    row = silhouette_errors.silhouette_row(_disk(30, 30, 14).astype(float), mask, 2)
    assert row["mask+2px"] > row["mask+1px"] > row["iou@0.5"] > row["mask-1px"]
    assert row["precision"] < 1.0 == row["recall"]


def test_a_soft_edge_spreads_the_thresholds():
    ys, xs = np.mgrid[:64, :64]
    alpha = np.clip((14 - np.hypot(xs - 30, ys - 30)) / 6 + 0.5, 0, 1)  # a 6 px ramp at r = 14
    row = silhouette_errors.silhouette_row(alpha, _disk(30, 30, 14), 1)
    # the mask's edge sits at opacity 0.5: both other thresholds miss it by ~1 px all round
    assert row["iou@0.5"] > max(row["iou@0.3"], row["iou@0.7"]) + 0.05


def test_the_bench_runs_on_a_checkpoint(tmp_path, capsys):
    assert silhouette_errors.main([str(smallest_run(tmp_path)), "--frames", "1", "--max-shift", "1"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert out[-1].startswith("summary: iou=") and out[-1].endswith("frames=1")


def test_the_bench_reads_training_frames_when_asked(tmp_path, capsys):
    ckpt = smallest_run(tmp_path)
    assert (
        silhouette_errors.main([str(ckpt), "--frames", "1", "--max-shift", "1", "--split", "training"]) == 0
    )
    out = capsys.readouterr().out
    assert "training frames [0]" in out and out.strip().splitlines()[-1].endswith("frames=1")
