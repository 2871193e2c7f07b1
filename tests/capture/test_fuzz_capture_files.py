"""Fuzzed capture files (hypothesis): image bytes (noise, cut and bit-flipped PNGs, PNG
headers declaring any size), camera calibrations and THUman4.0 ``calibration.json`` entries
either read correctly or raise AssetError / TexvocabError naming the file, never another
exception; what the checks accept is a usable camera."""

import json
import pickle
import shutil

import numpy as np
import pytest
from bad_files import png_bytes, png_declaring
from humannerf_cases import make_truth, write_standin
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from texvocab.body import default_body
from texvocab.capture import open as open_capture
from texvocab.capture.calibration_checks import CameraFields, check_camera
from texvocab.capture.camera import Camera
from texvocab.capture.image_reader import MAX_PIXELS, image_size, read_image, read_mask
from texvocab.capture.motion import make_sequence
from texvocab.capture.synth import SynthSettings, default_cameras, synthesize
from texvocab.errors import AssetError, TexvocabError

FUZZ = settings(
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
PNG = png_bytes((24, 16), seed=3)


def _flipped(data: bytes, flips: list[tuple[int, int]]) -> bytes:
    out = bytearray(data)
    for at, bit in flips:
        out[at % len(out)] ^= 1 << bit
    return bytes(out)


DIMS = st.one_of(st.integers(1, 64), st.integers(100_000, 2**31 - 1))
IMAGE_BYTES = st.one_of(
    st.binary(max_size=600),
    st.integers(0, len(PNG)).map(lambda n: PNG[:n]),
    st.lists(st.tuples(st.integers(0, 10**6), st.integers(0, 7)), min_size=1, max_size=6).map(
        lambda f: _flipped(PNG, f)
    ),
    st.tuples(DIMS, DIMS).map(lambda wh: png_declaring(*wh)),
)


@FUZZ
@given(IMAGE_BYTES)
def test_image_files(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("img") / "frame.png"
    path.write_bytes(data)
    try:
        w, h = image_size(path)
    except AssetError as e:
        assert str(e).startswith(f"{path}: ")
        return
    assert 1 <= w * h <= MAX_PIXELS
    for read, shape in ((read_image, (h, w, 3)), (read_mask, (h, w))):
        try:
            out = read(path)
        except AssetError as e:
            assert str(e).startswith(f"{path}: ")
            continue
        assert out.shape == shape
        assert out.dtype == bool or (np.isfinite(out).all() and 0 <= out.min() and out.max() <= 1)


GOOD = default_cameras(SynthSettings(ring_views=1, raised_views=0, size=32))[0]
FIELDS = CameraFields.keyed("", "K", "R", "t", "dist", "size")
NUMBERS = st.one_of(
    st.sampled_from([0.0, 1.0, -1.0, 1e-9, 1e6, 1e12, np.nan, np.inf, -np.inf]),
    st.floats(-1e3, 1e3),
)
ENTRY = st.sampled_from([("K", (3, 3)), ("R", (3, 3)), ("t", (3,)), ("dist", (5,))]).flatmap(
    lambda kv: st.tuples(st.just(kv[0]), st.tuples(*(st.integers(0, n - 1) for n in kv[1])), NUMBERS)
)


SIDES = st.one_of(st.just(32), st.integers(-2, 10**6))


@FUZZ
@given(st.lists(ENTRY, min_size=1, max_size=4), SIDES, SIDES)
def test_calibrations(edits, width, height):
    arrays = {k: getattr(GOOD, k).copy() for k in ("K", "R", "t", "dist")}
    for key, index, value in edits:
        arrays[key][index] = value
    cam = Camera(arrays["K"], arrays["R"], arrays["t"], width, height, arrays["dist"])
    try:
        check_camera(cam, "calib.json", FIELDS)
    except AssetError as e:
        assert str(e).startswith("calib.json: camera ''")
        return
    # accepted: a pinhole camera whose rays are finite and whose undistortion stays finite
    assert np.allclose(cam.K[2], (0, 0, 1)) and cam.K[0, 0] > 0 and cam.K[1, 1] > 0
    assert np.allclose(cam.R @ cam.R.T, np.eye(3), atol=1e-3) and np.linalg.det(cam.R) > 0
    small = Camera(cam.K, cam.R, cam.t, min(cam.width, 64), min(cam.height, 64), cam.dist)
    _, dirs = small.pixel_rays()
    assert np.isfinite(dirs.numpy()).all()
    assert np.isfinite(small.undistort_image(np.ones((small.height, small.width), np.float32))).all()


@pytest.fixture(scope="module")
def thuman(tmp_path_factory):
    poses, trans = make_sequence([("walk", 2)], seed=1)
    settings = SynthSettings(ring_views=2, raised_views=0, size=32, texture_size=64)
    root = tmp_path_factory.mktemp("fuzz_thuman") / "cap"
    return synthesize(root, poses, trans, 1, default_body(), settings, "thuman", progress=False)


JSON_JUNK = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-(10**12), 10**12), st.floats(), st.text(max_size=4)),
    lambda inner: st.one_of(
        st.lists(inner, max_size=10), st.dictionaries(st.text(max_size=3), inner, max_size=3)
    ),
    max_leaves=12,
)


@FUZZ
@given(st.sampled_from(["K", "R", "T", "D", "imgSize", "camera", "file"]), JSON_JUNK)
def test_thuman_calibration_entries(thuman, tmp_path_factory, where, junk):
    root = tmp_path_factory.mktemp("cal") / "cap"
    shutil.copytree(thuman, root)
    path = root / "calibration.json"
    calib = json.loads(path.read_text())
    if where == "file":
        calib = junk
    elif where == "camera":
        calib["cam01"] = junk
    else:
        calib["cam00"][where] = junk
    path.write_text(json.dumps(calib))
    try:
        cap = open_capture(root)
    except TexvocabError as e:
        assert str(root) in str(e)
        return
    assert cap.num_views == 2
    cap.check_image_sizes()


@pytest.fixture(scope="module")
def humannerf(tmp_path_factory):
    body = default_body()
    return write_standin(tmp_path_factory.mktemp("fuzz_hn") / "subject", body, make_truth(body))


PICKLE_JUNK = st.one_of(
    JSON_JUNK,
    st.sampled_from([np.zeros(()), np.zeros((3, 3)), np.zeros((4, 4)), np.eye(4) * 1e12, np.full(5, np.nan)]),
    st.lists(NUMBERS, min_size=1, max_size=16).map(np.asarray),
)


@FUZZ
@given(
    st.sampled_from(["cameras.pkl", "mesh_infos.pkl"]),
    st.sampled_from(["frame_000000", "frame_000003"]),
    st.sampled_from(
        ["intrinsics", "extrinsics", "distortions", "Rh", "Th", "poses", "tpose_joints", "entry"]
    ),
    PICKLE_JUNK,
)
def test_humannerf_pickle_entries(humannerf, tmp_path_factory, fname, frame, key, junk):
    root = tmp_path_factory.mktemp("hn") / "subject"
    shutil.copytree(humannerf, root)
    data = pickle.loads((root / fname).read_bytes())
    if key == "entry":
        data[frame] = junk
    else:
        data[frame][key] = junk
    (root / fname).write_bytes(pickle.dumps(data))
    try:
        cap = open_capture(root)
    except TexvocabError as e:
        assert str(root) in str(e)
        return
    assert cap.num_views == 1
    cap.check_image_sizes()
