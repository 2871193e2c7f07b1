"""Fold-region metrics on a made-up pair: the region is where truth and its rest-fold
rendering differ, and the metrics see only those pixels."""

import numpy as np

from texvocab.capture.fold_regions import FOLD_THRESHOLD, FoldRegions, fold_region
from texvocab.metrics import psnr, ssim
from texvocab.metrics.fold_region import fold_region_metrics, ssim_map, summarise_fold


def _pair():
    rng = np.random.default_rng(0)
    truth = rng.uniform(0.2, 0.8, (48, 64, 3))
    rest = truth.copy()
    rest[10:30, 20:44] += 0.2  # the folds of this pose differ from the rest pose's here
    rest[40:44, 5:9] += 0.5 * FOLD_THRESHOLD  # below the threshold: not a fold pixel
    return truth, rest


def test_region_is_where_truth_and_rest_folds_differ_above_the_threshold():
    truth, rest = _pair()
    region = fold_region(truth, rest)
    expected = np.zeros((48, 64), bool)
    expected[10:30, 20:44] = True
    np.testing.assert_array_equal(region, expected)


def test_metrics_see_only_the_region():
    truth, rest = _pair()
    region = fold_region(truth, rest)
    outside = truth.copy()
    outside[~region] = 0.0  # wrong everywhere but the fold region
    m = fold_region_metrics(outside, truth, region)
    assert m["psnr_fold"] == 100.0 and m["fold_pixels"] == region.sum()
    assert psnr(outside, truth) < 20  # the whole image is far off
    inside = truth.copy()
    inside[region] += 0.1
    m = fold_region_metrics(inside, truth, region)
    assert abs(m["psnr_fold"] - 20.0) < 1e-6  # mse 0.01 on the region
    assert m["ssim_fold"] < ssim(inside, truth)  # the whole-image SSIM dilutes the error


def test_ssim_map_mean_is_ssim():
    truth, rest = _pair()
    assert abs(ssim_map(rest, truth).mean() - ssim(rest, truth)) < 1e-12


def test_empty_or_resized_region_gives_none_and_the_summary_skips_it():
    truth, rest = _pair()
    region = fold_region(truth, rest)
    assert fold_region_metrics(truth, truth, np.zeros_like(region)) is None
    assert fold_region_metrics(truth, truth, region[::2, ::2]) is None
    a = fold_region_metrics(rest, truth, region)
    b = fold_region_metrics(truth * 0.9, truth, region)
    s = summarise_fold([a, None, b])
    assert s["fold_images"] == 2
    assert abs(s["psnr_fold"] - (a["psnr_fold"] + b["psnr_fold"]) / 2) < 1e-9
    assert s["psnr_fold_sem"] > 0 and summarise_fold([None])["psnr_fold"] is None


def test_regions_round_trip_through_the_capture_file(tmp_path):
    rng = np.random.default_rng(1)
    masks = rng.uniform(size=(3, 2, 17, 23)) > 0.7
    FoldRegions.save(tmp_path, [5, 6, 7], [0, 1], masks)
    regions = FoldRegions.load(tmp_path)
    np.testing.assert_array_equal(regions.region(6, 1), masks[1, 1])
    assert regions.region(4, 0) is None and FoldRegions.load(tmp_path / "missing") is None


def test_drawn_metrics_leave_out_the_pixels_the_render_leaves_empty():
    """With the render's opacity: the fold pixels it covers are scored apart, and the
    share it leaves empty is counted; an empty render has no drawn score."""
    truth, rest = _pair()
    region = fold_region(truth, rest)
    pred = truth.copy()
    pred[10:20, 20:44] = 0.0  # the region's top half: not drawn (background)
    pred[20:30, 20:44] += 0.1  # its bottom half: drawn, off by 0.1
    alpha = np.ones(region.shape)
    alpha[10:20, 20:44] = 0.2
    m = fold_region_metrics(pred, truth, region, alpha)
    assert abs(m["fold_empty"] - 0.5) < 1e-12
    assert abs(m["psnr_fold_drawn"] - 20.0) < 1e-6  # only the drawn half's mse 0.01
    assert m["psnr_fold"] < m["psnr_fold_drawn"] - 5  # the empty half dominates the region
    none_drawn = fold_region_metrics(pred, truth, region, np.zeros(region.shape))
    assert none_drawn["psnr_fold_drawn"] is None and none_drawn["fold_empty"] == 1.0
    assert "psnr_fold_drawn" not in fold_region_metrics(pred, truth, region)
    s = summarise_fold([m, none_drawn])
    assert s["psnr_fold_drawn"] == m["psnr_fold_drawn"] and s["fold_empty"] == 0.75
