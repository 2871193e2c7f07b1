"""The HumanNeRF reader on a stand-in the tests write themselves from a synthetic person
(one 64² camera, 10 frames): cameras, poses and root translation against the truth,
distortion undone on load, the one-camera split (last 20 % novel, training frames scored
as a seen view), a missing mask, a corrupt image, a malicious pickle, bad fields, and
check-assets."""

import dataclasses
import logging
import os
import pickle
import shutil

import numpy as np
import pytest
import torch
from humannerf_cases import DIST, FRAMES, distort, make_truth, smooth, write_standin
from train_cases import SMALLEST_SET

from texvocab.body import default_body
from texvocab.capture import detect_layout
from texvocab.capture import open as open_capture
from texvocab.cli.assets import check_path
from texvocab.cli.main import main
from texvocab.errors import AssetError, TexvocabError
from texvocab.geometry.rotations import rotvec_to_rotmat
from texvocab.pipeline.evaluate import build_sets, format_table
from texvocab.pipeline.model import texmap_settings, train_views
from texvocab.pipeline.settings import DataSettings, Settings


@pytest.fixture(scope="module")
def body():
    return default_body()


@pytest.fixture(scope="module")
def truth(body):
    return make_truth(body)


@pytest.fixture(scope="module")
def standin(tmp_path_factory, body, truth):
    return write_standin(tmp_path_factory.mktemp("hn") / "subject", body, truth)


def copy_of(standin, tmp_path):
    return shutil.copytree(standin, tmp_path / "subject")


def test_reads_cameras_poses_and_root_translation(standin, body, truth):
    poses, trans, cam, _ = truth
    assert detect_layout(standin) == "humannerf"
    cap = open_capture(standin, body=body)
    assert cap.layout == "humannerf" and cap.num_views == 1 and cap.num_frames == FRAMES
    assert cap.frame_ids == list(range(FRAMES))
    c = cap.cameras[0]
    assert (c.width, c.height) == (64, 64)
    np.testing.assert_allclose(c.K, cam.K, atol=1e-4)
    np.testing.assert_allclose(c.R, cam.R, atol=1e-9)
    np.testing.assert_allclose(c.t, cam.t, atol=1e-9)
    assert not c.dist.any()
    np.testing.assert_allclose(cap.rest_joints, body.rest_joints.numpy(), atol=1e-6)
    for t in range(FRAMES):
        want = body.forward(torch.as_tensor(poses[t])[None], torch.as_tensor(trans[t])[None])
        got = cap.posed_body(t)
        np.testing.assert_allclose(got.vertices.numpy(), want.vertices.numpy(), atol=1e-4)
    np.testing.assert_allclose(cap.trans, trans, atol=1e-5)


def test_body_pelvis_goes_on_the_subjects_pelvis(tmp_path, body, truth):
    """A subject whose rest skeleton sits 3 cm off the body's: the body's pelvis is put
    where the subject's is in the world, R(Rh)·J0s + Th."""
    offset = np.array([0.02, -0.03, 0.01])
    root = write_standin(tmp_path / "s", body, truth, pelvis_offset=offset)
    cap = open_capture(root, body=body)
    infos = pickle.load(open(root / "mesh_infos.pkl", "rb"))
    for t in (0, 7):
        info = infos[f"frame_{t:06d}"]
        R = rotvec_to_rotmat(torch.as_tensor(info["Rh"].astype(np.float64))).numpy()
        subject_pelvis = R @ info["tpose_joints"][0] + info["Th"]
        np.testing.assert_allclose(cap.posed_body(t).joints[0, 0].numpy(), subject_pelvis, atol=1e-5)
    np.testing.assert_allclose(cap.rest_joints[0], body.rest_joints[0].numpy() + offset, atol=1e-6)


def test_distortion_is_undone_on_load(tmp_path, body, truth):
    root = write_standin(tmp_path / "s", body, truth, dist=DIST)
    # the images as on disk: the smoothed truth bleeds past the mask, which masked would cut
    cap = dataclasses.replace(open_capture(root, body=body), masked=False)
    np.testing.assert_allclose(cap.cameras[0].dist, DIST, atol=1e-6)
    for t in (0, 6):
        rgb, mask = truth[3][t]
        rgb = smooth(rgb)
        recorded = distort(rgb, cap.cameras[0], DIST)  # what the file holds
        inner = np.s_[4:-4, 4:-4]
        err_loaded = np.abs(cap.image(0, t)[inner] - rgb[inner]).mean()
        err_recorded = np.abs(recorded[inner] - rgb[inner]).mean()
        assert err_loaded < 0.5 * err_recorded, (err_loaded, err_recorded)
        loaded_mask, recorded_mask = cap.mask(0, t), distort(mask, cap.cameras[0], DIST)
        iou = (loaded_mask & mask).sum() / (loaded_mask | mask).sum()
        iou_recorded = (recorded_mask & mask).sum() / (recorded_mask | mask).sum()
        assert iou > 0.98 and 1 - iou < 0.5 * (1 - iou_recorded), (iou, iou_recorded)


def test_one_camera_split_holds_out_the_last_frames(standin, body):
    cap = open_capture(standin, body=body)
    assert cap.num_train == 8 and list(cap.novel_frames) == [8, 9]
    assert open_capture(standin, body=body, num_train=5).num_train == 5
    s = Settings()  # default eval_views (1, 5): no such views here, and none are needed
    assert train_views(cap, s) == [0] and texmap_settings(cap, s).views == (0,)
    with pytest.raises(TexvocabError, match=r"train_views=\[1\].*one camera"):
        train_views(cap, Settings(data=DataSettings(train_views=(1,), eval_views=())))
    sets = build_sets(cap, s, generated=())
    assert sets["novel_poses"].pairs == [(8, 0), (9, 0)]
    train = sets["training_poses"]
    assert len(train) == 2 and all(t < 8 and v == 0 for t, v in train.pairs)
    assert train.label == "seen view" and "held-out frames" in sets["novel_poses"].label
    table = {name: {"images": len(items), "views": items.label} for name, items in sets.items()}
    md = format_table(table, "ck.pt", "one camera")
    assert "| training_poses (seen view) | 2 |" in md and "Split: one camera." in md


def test_missing_mask_leaves_the_frame_out_with_one_warning(standin, tmp_path, body, caplog):
    root = copy_of(standin, tmp_path)
    os.remove(root / "masks" / "frame_000003.png")
    with caplog.at_level(logging.WARNING, logger="texvocab"):
        cap = open_capture(root, body=body)
    assert cap.num_frames == FRAMES - 1 and 3 not in cap.frame_ids
    assert cap.frame_ids == [0, 1, 2, 4, 5, 6, 7, 8, 9]
    warnings = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(warnings) == 1 and "frame_000003 (no mask)" in warnings[0]
    # the poses of the kept frames are still theirs
    np.testing.assert_allclose(cap.poses[3], open_capture(standin, body=body).poses[4])


@pytest.mark.parametrize("damage", ["garbage", "truncated"])
def test_corrupt_image_is_an_error_naming_the_file(standin, tmp_path, body, damage):
    root = copy_of(standin, tmp_path)
    bad = root / "images" / "frame_000002.png"
    data = bad.read_bytes()
    bad.write_bytes(b"not a png at all" if damage == "garbage" else data[: len(data) // 2])
    cap = open_capture(root, body=body)
    with pytest.raises(AssetError, match="frame_000002.png"):
        cap.image(0, 2)
    if damage == "garbage":  # check-assets reads every header
        assert any(line.startswith("FAIL") and "frame_000002.png" in line for line in check_path(root))


class _Exploit:
    def __reduce__(self):
        return (os.system, (f"touch {self.sentinel}",))


def test_malicious_pickle_is_refused(standin, tmp_path, body):
    root = copy_of(standin, tmp_path)
    sentinel = tmp_path / "ran"
    exploit = _Exploit()
    exploit.sentinel = sentinel
    cams = pickle.load(open(root / "cameras.pkl", "rb"))
    cams["frame_000000"]["distortions"] = exploit
    with open(root / "cameras.pkl", "wb") as fh:
        pickle.dump(cams, fh)
    with pytest.raises(AssetError, match=r"refusing to load .*cameras\.pkl.*system"):
        open_capture(root, body=body)
    assert not sentinel.exists()


def _edit(root, fname, frame, key, value):
    data = pickle.load(open(root / fname, "rb"))
    data[frame][key] = value
    with open(root / fname, "wb") as fh:
        pickle.dump(data, fh)


BAD_FIELDS = [  # (file, frame, key, value, what the error says)
    ("mesh_infos.pkl", "frame_000004", "poses", np.zeros(69), r"frame_000004: 'poses' has shape \(69,\)"),
    (
        "mesh_infos.pkl",
        "frame_000001",
        "Th",
        np.array([0, np.nan, 0.0]),
        r"frame_000001: 'Th' contains non-finite",
    ),
    ("cameras.pkl", "frame_000000", "intrinsics", np.eye(3) * 2, r"frame_000000 'intrinsics': last row"),
    (
        "cameras.pkl",
        "frame_000000",
        "extrinsics",
        np.diag([1.0, 1.0, 2.0, 1.0]),
        r"'extrinsics'\[:3, :3\]: is not a rotation",
    ),
    (
        "cameras.pkl",
        "frame_000005",
        "distortions",
        np.full(5, 0.01),
        r"frame_000005 'distortions' differs .* one fixed camera",
    ),
]


@pytest.mark.parametrize("fname,frame,key,value,message", BAD_FIELDS)
def test_bad_fields_are_named(standin, tmp_path, body, fname, frame, key, value, message):
    root = copy_of(standin, tmp_path)
    _edit(root, fname, frame, key, value)
    with pytest.raises(AssetError, match=message) as err:
        open_capture(root, body=body)
    assert fname in str(err.value)


def test_check_assets_on_the_standin(standin, capsys):
    assert main(["check-assets", str(standin)]) == 0
    out = capsys.readouterr().out
    assert "OK" in out and "humannerf capture, 1 view x 10 frames (8 training)" in out
    assert "one camera, so no held-out view: the last 2 frames (8..9)" in out


def test_one_camera_capture_trains_and_evaluates(standin, tmp_path, capsys):
    """No held-out view anywhere: train on the camera's training frames, evaluate the
    novel frames from it, and the training frames labelled as a seen view."""
    root = copy_of(standin, tmp_path)
    tiny = [
        "encoder=small",
        "field.hidden=16",
        "field.sdf_layers=1",
        "field.color_layers=1",
        "field.pos_freqs=2",
        *SMALLEST_SET,
    ]
    args = [a for item in tiny for a in ("--set", item)]
    assert main(["train", str(root), "--out", str(tmp_path / "run"), "--iterations", "2", *args]) == 0
    assert (root / "texvocab_cache" / "texmaps_32_views_0").is_dir()
    assert (
        main(
            [
                "eval",
                str(tmp_path / "run" / "checkpoint.pt"),
                str(root),
                "--per-set",
                "1",
                "--out",
                str(tmp_path / "eval"),
            ]
        )
        == 0
    )
    md = (tmp_path / "eval" / "metrics.md").read_text()
    assert "| training_poses (seen view) | 1 |" in md
    assert "| novel_poses (capture camera, held-out frames) | 1 |" in md
    assert "Split: one camera, no held-out view: novel_poses are the last 2 of 10 frames" in md
    capsys.readouterr()


def test_the_body_is_fitted_to_the_subjects_rest_joints(tmp_path, body, truth):
    """A subject with longer shins and a lower pelvis: open() fits the default body's
    skeleton to tpose_joints, keeps its pelvis on the subject's, and keys the texture-map
    cache by the fit."""
    from texvocab.method.texmap import TexmapSettings, cache_dir

    root = write_standin(tmp_path / "s", body, truth, pelvis_offset=(0.0, -0.02, 0.0))
    with open(root / "mesh_infos.pkl", "rb") as fh:
        infos = pickle.load(fh)
    rest = next(iter(infos.values()))["tpose_joints"].copy()
    for knee, ankle in ((4, 7), (5, 8)):
        rest[ankle] = rest[knee] + 1.12 * (rest[ankle] - rest[knee])
    for info in infos.values():
        info["tpose_joints"] = rest
    with open(root / "mesh_infos.pkl", "wb") as fh:
        pickle.dump(infos, fh)
    plain = open_capture(root, body=body, fit_body=False)
    fitted = open_capture(root, body=body)
    assert np.abs(plain.body.rest_joints.numpy() - rest).max() > 0.02
    np.testing.assert_allclose(fitted.body.rest_joints.numpy(), rest, atol=1e-5)
    assert fitted.meta["body_fit"].startswith("skeleton-") and "body_fit" not in plain.meta
    for t in (0, 7):
        info = infos[f"frame_{t:06d}"]
        R = rotvec_to_rotmat(torch.as_tensor(info["Rh"].astype(np.float64))).numpy()
        np.testing.assert_allclose(
            fitted.posed_body(t).joints[0, 0].numpy(), R @ rest[0] + info["Th"], atol=1e-5
        )
    s = TexmapSettings()
    assert cache_dir(fitted, s) != cache_dir(plain, s)


def test_contact_sheet_of_a_real_capture_leaves_its_folder_alone(standin, tmp_path, monkeypatch, capsys):
    from disk_snapshot import snapshot

    root = copy_of(standin, tmp_path)
    before = snapshot(root)
    monkeypatch.chdir(tmp_path)
    assert main(["contact-sheet", str(root)]) == 0
    assert snapshot(root) == before
    assert (tmp_path / "contact_sheet_subject.png").is_file()
    capsys.readouterr()
