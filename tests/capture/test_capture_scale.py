"""Capture.scaled: images, masks and cameras resized together (a 1024² capture at 512²)."""

import numpy as np
import pytest

from texvocab.capture import open as open_capture
from texvocab.errors import AssetError


def test_half_scale_averages_pixels_and_keeps_the_cameras_aligned(capture):
    full = open_capture(capture)
    half = full.scaled(0.5)
    v, t = 1, 2
    img, small = full.image(v, t), half.image(v, t)
    assert small.shape == (full.cameras[v].height // 2, full.cameras[v].width // 2, 3)
    boxed = img.reshape(small.shape[0], 2, small.shape[1], 2, 3).mean((1, 3))
    assert np.abs(small - boxed).max() < 1e-5
    m, sm = full.mask(v, t), half.mask(v, t)
    assert sm.shape == small.shape[:2] and sm.dtype == bool
    share = m.reshape(sm.shape[0], 2, sm.shape[1], 2).mean((1, 3))
    assert (sm == (share > 0.5)).all()
    # the same world point lands on the same place of the scene in both images
    joints = full.posed_body(t).joints[0].numpy()
    px_full, _ = full.cameras[v].project(joints)
    px_half, _ = half.cameras[v].project(joints)
    assert np.abs((px_full + 0.5) * 0.5 - (px_half + 0.5)).max() < 1e-6
    assert half.scaled(1.0).cameras[v].width == full.cameras[v].width  # relative to disk
    assert half.scaled(0.25).image(v, t).shape[0] == full.cameras[v].height // 4


@pytest.mark.parametrize("factor", [0.0, -0.5, 1.5, float("nan")])
def test_a_scale_outside_0_1_is_refused(capture, factor):
    with pytest.raises(AssetError, match="image scale"):
        open_capture(capture).scaled(factor)


def test_large_captures_open_at_half_size_by_default(capture):
    from texvocab.capture import auto_image_scale

    cams = open_capture(capture).cameras
    assert auto_image_scale(cams) == 1.0  # 64²: as on disk
    big = [c.scaled(16.0) for c in cams]  # 1024²
    assert auto_image_scale(big) == 0.5
    assert auto_image_scale([c.scaled(30.0) for c in cams]) == 0.25  # 1920² -> 480²
    assert open_capture(capture, image_scale=0.5).cameras[0].width == cams[0].width // 2


def test_real_captures_are_black_outside_their_masks(capture, tmp_path):
    """A capture without texvocab's generator record is a real one: its images read black
    where the mask is not, the synthetic capture's as they are on disk."""
    import shutil

    from texvocab.capture.capture import SYNTH_META

    real = tmp_path / "real"
    shutil.copytree(capture, real, ignore=shutil.ignore_patterns("texvocab_cache"))
    (real / SYNTH_META).unlink()
    synth, cap = open_capture(capture), open_capture(real, num_train=4)
    assert not synth.masked and cap.masked
    img = synth.image(0, 1).copy()
    img[~synth.mask(0, 1)] = 0.7  # stands for a studio background on disk
    from texvocab.io.images import save_png

    save_png(cap.image_paths[1][0], img)
    out = cap.image(0, 1)
    assert (out[~cap.mask(0, 1)] == 0).all()
    assert np.abs(out[cap.mask(0, 1)] - img[cap.mask(0, 1)]).max() < 1 / 255 + 1e-6
