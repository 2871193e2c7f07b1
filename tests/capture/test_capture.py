"""Synthetic captures in both layouts, read back by the readers: cameras, poses, joint
reprojection, mask vs silhouette, pose-dependent folds, and bad input."""

import json
import shutil

import numpy as np
import pytest
import torch

from texvocab.body import default_body
from texvocab.capture import open as open_capture
from texvocab.capture.motion import make_sequence
from texvocab.capture.synth import SynthRenderer, SynthSettings, default_cameras, synthesize
from texvocab.errors import AssetError, TexvocabError
from texvocab.geometry.raster import rasterize_mesh

SETTINGS = SynthSettings(ring_views=3, raised_views=1, size=128, texture_size=256)


@pytest.fixture(scope="module")
def body():
    return default_body()


@pytest.fixture(scope="module")
def motion():
    poses, trans = make_sequence([("walk", 2), ("squat", 2)], seed=3)
    return poses, trans


@pytest.fixture(scope="module")
def captures(tmp_path_factory, body, motion):
    root = tmp_path_factory.mktemp("captures")
    out = {}
    for layout in ("zju", "thuman"):
        out[layout] = synthesize(
            root / layout, *motion, num_train=3, body=body, settings=SETTINGS, layout=layout, progress=False
        )
    return out


@pytest.mark.parametrize("layout", ["zju", "thuman"])
def test_reader_reads_what_the_generator_wrote(captures, body, motion, layout):
    cap = open_capture(captures[layout], body=body)
    assert cap.layout == layout and cap.num_views == 4 and cap.num_frames == 4
    assert list(cap.train_frames) == [0, 1, 2] and list(cap.novel_frames) == [3]
    for cam, ref in zip(cap.cameras, default_cameras(SETTINGS)):
        np.testing.assert_allclose(cam.K, ref.K, atol=1e-9)
        np.testing.assert_allclose(cam.R, ref.R, atol=1e-9)
        np.testing.assert_allclose(cam.t, ref.t, atol=1e-9)
    poses, trans = motion
    for t in range(4):
        truth = body.forward(torch.as_tensor(poses[t])[None], torch.as_tensor(trans[t])[None])
        read = cap.posed_body(t)
        for cam in cap.cameras:
            p_true, _ = cam.project(truth.joints[0].numpy())
            p_read, _ = cam.project(read.joints[0].numpy())
            assert np.abs(p_true - p_read).max() < 1.0  # joints reproject within 1 px


@pytest.mark.parametrize("layout", ["zju", "thuman"])
def test_mask_matches_reprojected_silhouette(captures, body, layout):
    cap = open_capture(captures[layout], body=body)
    for t in range(cap.num_frames):
        verts = cap.posed_body(t).vertices[0]
        for v, cam in enumerate(cap.cameras):
            sil = rasterize_mesh(verts, body.faces, cam).mask.numpy()
            mask = cap.mask(v, t)
            iou = (sil & mask).sum() / (sil | mask).sum()
            assert iou >= 0.98, (layout, t, v, iou)
            img = cap.image(v, t)
            assert img[mask].mean() > 0.1 and img[~mask].mean() < 0.01  # body lit, background black


def test_folds_follow_the_elbow_angle(body):
    renderer = SynthRenderer(body, SynthSettings())  # the default capture's settings
    g = renderer.garment
    bent, straight = np.zeros((24, 3), np.float32), np.zeros((24, 3), np.float32)
    bent[16] = straight[16] = [0, 0, -np.radians(75)]  # arm down
    bent[18] = [0, -np.radians(60), 0]  # elbow flexed 60° vs straight
    # texture space: the change is confined to the rest surface near the left elbow
    diff = np.abs(g.fold_map(bent) - g.fold_map(straight))[g.covered]
    assert diff.max() > 0.5
    near = np.linalg.norm(g.points - g.joints[18], axis=1) < 0.2
    assert diff[near].sum() / diff.sum() > 0.97
    # image space, same geometry: pixels that change lie near the projected elbow
    cams = default_cameras(SynthSettings())
    a = renderer.render(bent, np.zeros(3), cams)
    b = renderer.render(bent, np.zeros(3), cams, texture_pose=straight)
    changed = [np.abs(x[0] - y[0]).max(-1) > 0.05 for x, y in zip(a, b)]
    view = int(np.argmax([c.sum() for c in changed]))
    cam, changed = cams[view], changed[view]
    assert changed.sum() > 25
    elbow = body.forward(torch.as_tensor(bent)[None]).joints[0, 18].numpy()
    pix, depth = cam.project(elbow[None])
    ys, xs = np.nonzero(changed)
    radius_px = 0.2 * cam.K[0, 0] / depth[0]
    assert np.mean(np.hypot(xs - pix[0, 0], ys - pix[0, 1]) < radius_px) > 0.95
    renderer.close()


def _copy(src, tmp_path):
    dst = tmp_path / src.name
    shutil.copytree(src, dst)
    return dst


def test_missing_view_folder(captures, tmp_path, body):
    root = _copy(captures["zju"], tmp_path)
    shutil.rmtree(root / "Camera_B2")
    with pytest.raises(AssetError, match=r"annots\.npy: missing view folder .*Camera_B2"):
        open_capture(root, body=body)
    root = _copy(captures["thuman"], tmp_path / "t")
    shutil.rmtree(root / "masks" / "cam01")
    with pytest.raises(AssetError, match=r"calibration\.json: missing view folder .*masks/cam01"):
        open_capture(root, body=body)


def test_frame_count_mismatch(captures, tmp_path, body):
    root = _copy(captures["zju"], tmp_path)
    (root / "Camera_B3" / "000002.png").unlink()
    with pytest.raises(AssetError, match=r"Camera_B3: 3 images but annots\.npy lists 4 frames"):
        open_capture(root, body=body)
    root = _copy(captures["thuman"], tmp_path / "t")
    (root / "images" / "cam02" / "00000003.jpg").unlink()
    with pytest.raises(AssetError, match=r"cam02: 3 images .*frame count mismatch"):
        open_capture(root, body=body)


def test_camera_count_mismatch(captures, tmp_path, body):
    root = _copy(captures["thuman"], tmp_path)
    calib = json.loads((root / "calibration.json").read_text())
    calib["cam09"] = calib["cam00"]
    (root / "calibration.json").write_text(json.dumps(calib))
    with pytest.raises(AssetError, match=r"camera count mismatch: 5 calibrated cameras, 4 folders"):
        open_capture(root, body=body)
    root = _copy(captures["zju"], tmp_path / "z")
    annots = np.load(root / "annots.npy", allow_pickle=True).item()
    annots["cams"]["K"] = annots["cams"]["K"][:3]
    np.save(root / "annots.npy", annots, allow_pickle=True)
    with pytest.raises(AssetError, match="camera count mismatch"):
        open_capture(root, body=body)


def test_non_finite_calibration(captures, tmp_path, body):
    root = _copy(captures["thuman"], tmp_path)
    calib = json.loads((root / "calibration.json").read_text())
    calib["cam01"]["T"][2] = float("nan")
    (root / "calibration.json").write_text(json.dumps(calib))
    with pytest.raises(AssetError, match=r"calibration\.json: camera 'cam01' 'T': holds NaN or inf"):
        open_capture(root, body=body)


def test_bad_poses_write_nothing(tmp_path, body):
    poses = np.zeros((2, 24, 3), np.float32)
    poses[1, 18, 0] = np.nan
    with pytest.raises(TexvocabError, match=r"pose\[1, 18\] \(left_elbow\) is not finite"):
        synthesize(tmp_path / "cap", poses, np.zeros((2, 3)), 1, body, SETTINGS, progress=False)
    assert list(tmp_path.iterdir()) == []
