"""``texvocab eval``'s sets, aggregation and report: full test splits by default, means
with their standard errors and image counts, FID only from 50 images, KID from 2, a
progress bar. A fake capture and a stand-in renderer keep it fast (the real pipeline
runs end to end in test_train.py)."""

import json
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from texvocab.cli.main import main
from texvocab.errors import TexvocabError
from texvocab.metrics import frechet, frechet_distance_from_features, inception_features, kid_from_features
from texvocab.pipeline import evaluate
from texvocab.pipeline.evaluate import (
    CaptureItems,
    build_sets,
    evaluate_sets,
    format_table,
    sem,
    spread,
    summarise,
    write_report,
)

SIZE = 6


class FakeCapture:
    """The attributes build_sets reads: frame t's pose is filled with t, its image with
    (t + v) / 100 in view v; image() calls are counted."""

    def __init__(self, num_train: int = 20, num_novel: int = 7, views: int = 6):
        t = num_train + num_novel
        self.poses = np.arange(t, dtype=np.float32)[:, None, None] * np.ones((1, 24, 3), np.float32)
        self.trans = np.zeros((t, 3), np.float32)
        self.cameras = [SimpleNamespace(name=f"view{v}", width=64, height=64) for v in range(views)]
        self.num_views, self.root, self.frame_ids = views, "fake", list(range(t))
        self.train_frames, self.novel_frames = range(num_train), range(num_train, t)
        self.synthetic = None
        self.reads = 0

    def image(self, view: int, frame: int) -> np.ndarray:
        self.reads += 1
        return np.full((SIZE, SIZE, 3), (frame + view) / 100, np.float32)

    def mask(self, view: int, frame: int) -> np.ndarray:
        return np.full((SIZE, SIZE), (frame, view) not in self.empty_masks)

    empty_masks: tuple = ()


SETTINGS = SimpleNamespace(data=SimpleNamespace(eval_views=(1, 5)))


def frames_views(items) -> list[tuple[int, int]]:
    """(frame, view) of each item, read back from its pose and camera."""
    return [(int(pose[0, 0]), int(cam.name[4:])) for pose, _, cam, _, _ in items]


def test_build_sets_defaults_to_all_novel_frames_and_as_many_spread_training_frames():
    cap = FakeCapture(num_train=20, num_novel=7)
    sets = build_sets(cap, SETTINGS)
    assert list(sets) == ["training_poses", "novel_poses"]  # not synthetic: no generated set
    assert cap.reads == 0  # images are read when an item is used, not when the set is built
    novel = frames_views(sets["novel_poses"])
    assert novel == [(t, v) for t in range(20, 27) for v in (1, 5)]
    train = frames_views(sets["training_poses"])
    frames = sorted({t for t, _ in train})
    assert len(train) == len(novel) == 14 and [v for _, v in train] == [1, 5] * 7
    assert frames[0] == 0 and frames[-1] == 19  # spread over all training frames
    gaps = np.diff(frames)
    assert gaps.max() - gaps.min() <= 1  # evenly
    pose, trans, cam, gt, mask = sets["novel_poses"][3]
    assert cam is cap.cameras[5] and gt.shape == (SIZE, SIZE, 3) and gt[0, 0, 0] == pytest.approx(0.26)
    assert mask.all() and pose[0, 0] == 21


def test_build_sets_per_set_limits_both_sets_and_is_validated():
    cap = FakeCapture(num_train=20, num_novel=7)
    sets = build_sets(cap, SETTINGS, per_set=3)
    assert sorted({t for t, _ in frames_views(sets["novel_poses"])}) == [20, 23, 26]
    assert sorted({t for t, _ in frames_views(sets["training_poses"])}) == [0, 9, 19]
    assert len(build_sets(cap, SETTINGS, per_set=50)["training_poses"]) == 14  # = novel count
    for bad in (0, -2):
        with pytest.raises(TexvocabError, match="--per-set must be at least 1"):
            build_sets(cap, SETTINGS, per_set=bad)
    no_novel = build_sets(FakeCapture(num_train=9, num_novel=0), SETTINGS)
    assert list(no_novel) == ["training_poses"] and len(no_novel["training_poses"]) == 18


def test_build_sets_refuses_missing_or_tiny_views_and_leaves_out_empty_masks(caplog):
    with pytest.raises(TexvocabError, match=r"eval_views \[1, 5\]: fake has views 0..3"):
        build_sets(FakeCapture(views=4), SETTINGS)
    tiny = FakeCapture()
    tiny.cameras[5].width = 10
    with pytest.raises(TexvocabError, match="view 5 is 10x"):
        build_sets(tiny, SETTINGS)
    cap = FakeCapture(num_train=20, num_novel=7)
    cap.empty_masks = ((21, 5), (22, 1))
    with caplog.at_level("WARNING", logger="texvocab"):
        sets = build_sets(cap, SETTINGS)
    pairs = frames_views(sets["novel_poses"])
    assert len(pairs) == 12 and (21, 5) not in pairs and (22, 1) not in pairs
    assert "2 of 14 images have an empty mask (first: frame 21, view 5)" in caplog.text


def test_spread_and_capture_items():
    assert spread(range(10), 1) == [0] and spread(range(10), 20) == list(range(10))
    assert spread(range(10, 20), 4) == [10, 13, 16, 19] and spread([], 3) == []
    cap = FakeCapture()
    items = CaptureItems(cap, [(2, 1), (3, 5)])
    assert len(items) == 2 and frames_views(items[1:]) == [(3, 5)] and cap.reads == 1


def test_sem_and_summarise():
    vals = [27.0, 27.5, 28.5, 26.0]
    assert sem(vals) == pytest.approx(np.std(vals, ddof=1) / 2.0) and sem([1.0]) is None
    per = [{"psnr_bbox": v, "ssim_bbox": 0.9, "lpips": None, "seconds": 1.0} for v in vals]
    s = summarise(per)
    assert s["psnr_bbox"] == pytest.approx(np.mean(vals)) and s["psnr_bbox_sem"] == pytest.approx(sem(vals))
    assert s["ssim_bbox_sem"] == 0.0 and s["lpips"] is None and s["lpips_sem"] is None
    assert "seconds_sem" not in s


def _fake_extractor(x: torch.Tensor) -> torch.Tensor:
    """Stands in for Inception: (B, 3, 299, 299) -> (B, 3) channel means."""
    return x.mean((2, 3))


@pytest.fixture
def fake_render(monkeypatch):
    """render_view returns the truth darkened by 10 % (found by the item's pose), so PSNR
    differs per image; the Inception extractor is the channel-mean stand-in."""
    truth = {}

    def render_view_rgba(model, pose, trans, camera, march, scale=1.0):
        rgb = truth[(int(pose[0, 0]), camera.name)]
        return rgb * 0.9, np.ones(rgb.shape[:2], np.float32), SimpleNamespace(seconds=0.5)

    monkeypatch.setattr(evaluate, "render_view_rgba", render_view_rgba)
    monkeypatch.setattr(frechet, "inception_extractor", lambda extractor=None: _fake_extractor)
    monkeypatch.setattr(
        evaluate,
        "evaluate_pair",
        lambda pred, gt, mask, lpips_model=None: {
            "psnr_bbox": float(-10 * np.log10(np.mean((pred - gt) ** 2))),
            "ssim_bbox": 0.9,
            "psnr_full": 30.0,
            "ssim_full": 0.95,
            "lpips": None,
        },
    )
    return truth


def test_evaluate_sets_reports_means_sems_counts_fid_from_50_and_kid(fake_render, capsys):
    cap = FakeCapture(num_train=40, num_novel=30)
    sets = build_sets(cap, SETTINGS)
    for items in sets.values():
        for pose, _, cam, gt, _ in items:
            fake_render[(int(pose[0, 0]), cam.name)] = gt
    sets["few"] = [sets["novel_poses"][i] for i in range(3)]
    table, records, grids = evaluate_sets(None, sets, None, grid_rows=2, progress=True)
    err = capsys.readouterr().err
    assert "eval" in err and "123/123" in err and "img" in err  # 60 + 60 + 3 images
    big, few = table["novel_poses"], table["few"]
    assert big["images"] == 60 and table["training_poses"]["images"] == 60 and few["images"] == 3
    psnrs = [r["psnr_bbox"] for r in records if r["set"] == "novel_poses"]
    assert big["psnr_bbox"] == pytest.approx(np.mean(psnrs))
    assert big["psnr_bbox_sem"] == pytest.approx(np.std(psnrs, ddof=1) / np.sqrt(60))
    assert big["psnr_bbox_sem"] > 0
    gts = [it[3] for it in sets["novel_poses"]]
    f_gt = inception_features(gts, _fake_extractor)
    f_pred = inception_features([g * 0.9 for g in gts], _fake_extractor)
    assert big["fid"] == pytest.approx(frechet_distance_from_features(f_gt, f_pred), rel=1e-6)
    assert big["kid"] == pytest.approx(kid_from_features(f_gt, f_pred)[0], rel=1e-6)
    assert big["kid_std"] is None and few["fid"] is None and few["kid"] is not None
    assert (records[0]["frame"], records[0]["view"]) == (0, 1) and records[0]["seconds"] == 0.5
    assert len(grids["novel_poses"]) == 2 and len(grids["few"][0]) == 3
    evaluate_sets(None, {"few": sets["few"]}, None, progress=False)
    assert capsys.readouterr().err == ""


def test_evaluate_sets_without_inception_reports_none(fake_render, monkeypatch):
    monkeypatch.setattr(frechet, "inception_extractor", lambda extractor=None: None)
    items = [
        (
            np.full((24, 3), t, np.float32),
            np.zeros(3),
            SimpleNamespace(name="v"),
            np.full((SIZE, SIZE, 3), 0.1 * (t + 1), np.float32),
            np.ones((SIZE, SIZE), bool),
        )
        for t in range(3)
    ]
    for t in range(3):
        fake_render[(t, "v")] = items[t][3]
    table, _, _ = evaluate_sets(None, {"s": items}, None, progress=False)
    assert table["s"]["fid"] is None and table["s"]["kid"] is None and table["s"]["images"] == 3


ROW = {
    "images": 60,
    "psnr_bbox": 27.4142,
    "psnr_bbox_sem": 0.2271,
    "ssim_bbox": 0.93124,
    "ssim_bbox_sem": 0.00213,
    "psnr_full": 31.0,
    "psnr_full_sem": 0.1,
    "ssim_full": 0.97,
    "ssim_full_sem": 0.001,
    "lpips": None,
    "lpips_sem": None,
    "fid": 41.234,
    "kid": 0.01234,
    "kid_std": None,
    "seconds": 1.31,
}


def test_report_shows_mean_pm_sem_counts_and_fid_na_under_50(tmp_path):
    few = {**ROW, "images": 8, "fid": None, "kid": -0.0021, "kid_std": 0.0005}
    table = {"novel_poses": ROW, "generated_novel_poses": few}
    md = format_table(table, "ck.pt")
    header = md.splitlines()[0]
    assert "ck.pt" in header and "±" in header and "standard error" in header
    assert (
        "| novel_poses | 60 | 27.41 ± 0.23 | 0.9312 ± 0.0021 | 31.00 ± 0.10 | 0.9700 ± 0.0010 "
        "| n/a | 41.23 | 0.0123 | n/a | 1.31 |"
    ) in md
    assert "| generated_novel_poses | 8 |" in md and "| n/a (8 images) | -0.0021 (sd 0.0005) |" in md
    paths = write_report(
        tmp_path,
        table,
        [{"set": "novel_poses", "index": 0, "psnr_bbox": 27.0}],
        {"novel_poses": []},
        {"checkpoint": "ck.pt"},
    )
    assert paths[0].read_text() == md
    blob = json.loads(paths[1].read_text())
    g = blob["table"]["generated_novel_poses"]
    assert g["fid"] is None and g["images"] == 8 and g["psnr_bbox_sem"] == pytest.approx(0.2271)
    assert blob["images"][0]["psnr_bbox"] == 27.0 and blob["protocol"]["fid_min_images"] == 50


def test_eval_command_rejects_per_set_below_one(capsys, tmp_path):
    assert main(["eval", str(tmp_path / "none.pt"), str(tmp_path), "--per-set", "0"]) == 2
    err = capsys.readouterr().err
    assert err == "error: --per-set must be at least 1, got 0\n"


def test_silhouette_iou_thresholds_the_opacity_at_one_half():
    mask = np.zeros((4, 4), bool)
    mask[:2] = True  # 8 pixels
    alpha = np.zeros((4, 4), np.float32)
    alpha[:2, :2] = 0.9  # 4 inside
    alpha[3, 0] = 0.6  # 1 outside
    alpha[2, :] = 0.5  # not > 0.5
    assert evaluate.silhouette_iou(alpha, mask) == pytest.approx(4 / 9)
    assert evaluate.silhouette_iou(np.zeros((4, 4)), np.zeros((4, 4), bool)) is None
