"""Calibration that must be a camera and masks that can be a silhouette, in every reader:
each class of bad calibration (K's form, focal length, skew, distortion, rotation, image
size, a camera that does not see the subject) is one AssetError naming the file and field;
THUman's calibration.json and view folders as real data breaks them."""

import dataclasses
import json
import shutil

import numpy as np
import pytest
from PIL import Image

from texvocab.body import default_body
from texvocab.capture import open as open_capture
from texvocab.capture.calibration_checks import MAX_DEPTH, CameraFields, check_camera
from texvocab.capture.motion import make_sequence
from texvocab.capture.synth import SynthSettings, default_cameras, synthesize
from texvocab.errors import AssetError

FIELDS = CameraFields.keyed("calib ", "K", "R", "t", "dist", "size")
GOOD = default_cameras(SynthSettings(ring_views=1, raised_views=0, size=64))[0]


def _with(**change):
    cam = dataclasses.replace(GOOD, K=GOOD.K.copy(), R=GOOD.R.copy(), dist=GOOD.dist.copy())
    for key, edit in change.items():
        value = getattr(cam, key) if key in ("K", "R", "dist") else None
        setattr(cam, key, edit(value) if callable(edit) else edit)
    return cam


def _set(index, value):
    def edit(a):
        a[index] = value
        return a

    return edit


BAD = [  # (id, change, what the error says)
    ("K-last-row-zero", {"K": _set(2, 0.0)}, r"calib K: last row is \[0.0, 0.0, 0.0\]; expected \(0, 0, 1\)"),
    ("K-scaled", {"K": lambda k: 2 * k}, r"calib K: last row"),
    ("K-lower-triangle", {"K": _set((1, 0), 5.0)}, r"K\[1\]\[0\] is 5; expected 0 \(K is upper-triangular\)"),
    ("focal-negative", {"K": _set((0, 0), -100.0)}, r"focal lengths -100, .* expected both between"),
    ("focal-subnormal", {"K": _set((0, 0), 1.1e-308)}, r"focal lengths 1.1e-308, .* expected both between"),
    ("focal-huge", {"K": _set((1, 1), 1e9)}, r"and 100 x the image's longest side \(0.64 to 6400 px\)"),
    ("skew-1e6", {"K": _set((0, 1), 1e6)}, r"skew K\[0\]\[1\] = 1e\+06 px; expected at most 0.1 x fx"),
    ("dist-1e6", {"dist": _set(0, 1e6)}, r"calib dist: .* expected a lens model that moves none by more"),
    ("dist-folding", {"dist": _set(0, -3.0)}, r"folds the image back"),
    ("R-scaled", {"R": lambda r: 2 * r}, r"calib R: is not a rotation"),
    ("R-reflection", {"R": lambda r: -r}, r"det -1\); expected an orthonormal"),
    ("t-nan", {"t": np.array([0.0, np.nan, 3.0])}, r"calib t: holds NaN or inf"),
    ("size-huge", {"width": 100_000, "height": 100_000}, r"calib size: 100000x100000; expected .* 40 Mpx"),
    ("size-zero", {"width": 0}, r"calib size: 0x64"),
]


def test_the_good_camera_passes():
    assert check_camera(_with(), "calib", FIELDS) is not None
    real_lens = _with(dist=np.array([-0.45, 0.15, 0.003, -0.002, 0.06]))  # a ZJU-like lens
    check_camera(real_lens, "calib", FIELDS)


@pytest.mark.parametrize("case", BAD, ids=[c[0] for c in BAD])
def test_a_camera_that_cannot_be_is_named_by_file_and_field(case):
    _, change, words = case
    with pytest.raises(AssetError, match=words) as err:
        check_camera(_with(**change), "calib", FIELDS)
    assert str(err.value).startswith("calib: camera 'view0' calib ")


@pytest.fixture(scope="module")
def thuman(tmp_path_factory):
    """A THUman4.0-layout capture: 2 ring views, 48², 3 frames."""
    poses, trans = make_sequence([("walk", 3)], seed=2)
    settings = SynthSettings(ring_views=2, raised_views=0, size=48, texture_size=64)
    root = tmp_path_factory.mktemp("thuman") / "cap"
    return synthesize(root, poses, trans, 2, default_body(), settings, "thuman", progress=False)


def _copy(root, tmp_path, change):
    dst = tmp_path / "cap"
    shutil.copytree(root, dst)
    change(dst)
    return dst


def _calib(edit):
    def change(root):
        path = root / "calibration.json"
        calib = json.loads(path.read_text())
        path.write_text(json.dumps(edit(calib)))

    return change


def _turned_away(calib):
    """cam01 turned half round its x axis in place: the same centre, looking away."""
    flip = np.diag([1.0, -1.0, -1.0])
    cam = calib["cam01"]
    cam["R"] = (flip @ np.reshape(cam["R"], (3, 3))).reshape(-1).tolist()
    cam["T"] = (flip @ np.reshape(cam["T"], 3)).tolist()
    return calib


def _far(calib):
    calib["cam00"]["T"] = (np.asarray(calib["cam00"]["T"]) * 1e12).tolist()
    return calib


def _all_masks(value):
    def change(root):
        for p in (root / "masks").rglob("*.jpg"):
            with Image.open(p) as im:
                size = im.size
            Image.new("L", size, value).save(p, format="JPEG")

    return change


def _rename_first_image(root):
    first = sorted((root / "images" / "cam00").iterdir())[0]
    first.rename(first.with_name("frame_a.jpg"))


def _empty_view(root):
    for p in (root / "images" / "cam01").iterdir():
        p.unlink()


THUMAN_BAD = [
    ("camera-facing-away", _calib(_turned_away), r"camera 'cam01' \('R', 'T'\) does not see the subject"),
    ("T-times-1e12", _calib(_far), rf"m away; expected it 0.05..{MAX_DEPTH:g} m in front"),
    (
        "K-last-row-zero",
        _calib(lambda c: {**c, "cam00": {**c["cam00"], "K": c["cam00"]["K"][:6] + [0, 0, 0]}}),
        "'K': last row",
    ),
    (
        "calibration-a-list",
        lambda r: (r / "calibration.json").write_text("[1, 2]"),
        "holds list; expected a JSON object",
    ),
    (
        "calibration-not-utf8",
        lambda r: (r / "calibration.json").write_bytes(b'{"cam00": "\xff\xfe"}'),
        "not UTF-8 text",
    ),
    ("camera-a-string", _calib(lambda c: {**c, "cam00": "K"}), "camera 'cam00' holds str"),
    ("image-name-not-a-frame", _rename_first_image, "'frame_a' is not a frame number"),
    ("empty-view-folder", _empty_view, r"cam01: no images"),
    ("masks-all-empty", _all_masks(0), r"all 6 masks are empty"),
    ("masks-all-full", _all_masks(255), r"all 6 masks are full"),
]


def test_the_good_thuman_capture_opens(thuman):
    assert open_capture(thuman).num_views == 2


@pytest.mark.parametrize("case", THUMAN_BAD, ids=[c[0] for c in THUMAN_BAD])
def test_bad_thuman_calibration_and_folders_are_one_error(thuman, tmp_path, case):
    _, change, words = case
    root = _copy(thuman, tmp_path, change)
    with pytest.raises(AssetError, match=words) as err:
        open_capture(root)
    assert str(root) in str(err.value)
