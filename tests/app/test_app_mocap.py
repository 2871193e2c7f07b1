"""The viewer on mocap, in a real window (Xvfb, ImGui Test Engine): the raw AMASS-layout
sample seen from capture view 1 keeps the whole body in frame, head and feet, from its
first frame to its last; and the novelty overlay of a frame facing away from camera 0
reads as the same frame facing it (the vocabulary reads root-relative poses)."""

from __future__ import annotations

import os

import numpy as np
import pytest
from PIL import Image
from pose_file_cases import amass_file
from tiny_runs import smallest_run
from window_runs import run_window

pytestmark = pytest.mark.slow  # Xvfb windows

BACKGROUND = np.array((0.13, 0.14, 0.16)) * 255  # SceneOptions.background


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    return smallest_run(tmp_path_factory.mktemp("mocap"))


def ok(proc, rep):
    assert proc.returncode == 0 and rep["ok"], (rep.get("error"), rep.get("engine_log"), proc.stderr[-2000:])
    assert "Traceback" not in proc.stderr


def silhouette(png) -> np.ndarray:
    """The body's pixels in a 3D view image: those away from the background colour."""
    image = np.asarray(Image.open(png).convert("RGB")).astype(np.float32)
    return np.abs(image - BACKGROUND).max(-1) > 12


def test_capture_view_1_keeps_the_amass_sample_in_frame_head_to_feet(checkpoint, tmp_path):
    amass_file(tmp_path / "walk.npz", frames=151, rate=120.0)  # 1.25 s: 1.25 m along +X
    out = tmp_path / "views"
    # the default root choice, as texvocab render --root floor places it: the lowest foot
    # on the capture's floor, starting where the capture's subject starts; Follow keeps the
    # capture camera's view on the walking root (its 1.25 m would leave a fixed view)
    env = dict(os.environ, TEXVOCAB_TEST_OUT=str(out), TEXVOCAB_TEST_FOLLOW="1")
    proc, rep, _ = run_window(
        checkpoint, "mocap-frames", tmp_path, "--poses", str(tmp_path / "walk.npz"), env=env, timeout=300
    )
    ok(proc, rep)
    assert rep["camera_index"] == 1 and rep["frames_in_file"] == 151 and rep["root_choice"] == "floor"
    assert rep["follow"]
    assert [s["shown"] for s in rep["shots"]] == [0, 75, 150]
    for shot in rep["shots"]:
        w, h = shot["size"]
        assert w >= 200 and h >= 200, shot["size"]  # the view's size, letterboxed to the camera's
        body = silhouette(shot["png"])
        assert body.shape == (h, w)
        # the pixels that differ from the background are the body's (its depth buffer)
        depth = np.load(out / f"view1_frame{shot['frame']}_silhouette.npy")
        assert (body & depth).sum() / (body | depth).sum() > 0.9, shot["frame"]
        ys, xs = np.nonzero(body)
        top, bottom, left, right = ys.min(), h - 1 - ys.max(), xs.min(), w - 1 - xs.max()
        # the whole body: head and feet inside the frame with a margin, and tall in it
        margin = 0.02 * h
        assert top > margin and bottom > margin, (shot["frame"], top, bottom)
        assert left > margin and right > margin, (shot["frame"], left, right)
        assert ys.max() - ys.min() > 0.3 * h, shot["frame"]
        # the head and feet joints project inside the image, in front of the camera, and
        # the head lies above the feet
        for u, v in [shot["head_uv"], *shot["feet_uv"]]:
            assert 0 < u < w and 0 < v < h, (shot["frame"], u, v)
        assert all(z > 0 for z in shot["depths"])
        assert shot["head_uv"][1] < min(v for _, v in shot["feet_uv"])
    # the body walked its 1.25 m, the camera following; the left knee bends (the frames
    # differ)
    roots = np.array([s["root"] for s in rep["shots"]])
    assert np.linalg.norm(roots[-1] - roots[0]) == pytest.approx(1.25, abs=0.02)
    first, middle = (silhouette(s["png"]) for s in rep["shots"][:2])
    assert (first ^ middle).mean() > 0.002


def turned_away(path, facing) -> None:
    """``facing`` (an AMASS-layout file) with its root turned half a turn about the
    vertical (Z in AMASS's world): the same motion facing the other way, in place."""
    data = dict(np.load(facing))
    poses = data["poses"].copy()
    # R_z(180°) R_x(root): for the sample's root (+90° about x), a half turn about (0, 1, 1)/√2
    assert np.allclose(poses[:, :3], [np.pi / 2, 0, 0])
    poses[:, :3] = np.pi * np.array([0.0, 1.0, 1.0]) / np.sqrt(2)
    data["poses"] = poses
    np.savez(path, **data)


def test_the_novelty_of_a_mocap_frame_does_not_depend_on_where_it_faces(checkpoint, tmp_path):
    amass_file(tmp_path / "facing.npz", frames=5, rate=120.0)
    turned_away(tmp_path / "away.npz", tmp_path / "facing.npz")
    env = dict(
        os.environ,
        TEXVOCAB_TEST_OUT=str(tmp_path / "views"),
        TEXVOCAB_TEST_AWAY_POSES=str(tmp_path / "away.npz"),
    )
    proc, rep, _ = run_window(
        checkpoint, "mocap-novelty", tmp_path, "--poses", str(tmp_path / "facing.npz"), env=env, timeout=300
    )
    ok(proc, rep)
    assert rep["pose_condition"] == "root-relative" and rep["away_loaded"]
    facing, away = rep["facing"], rep["away"]
    assert facing["facing_camera0"] > 0.9 and away["facing_camera0"] < -0.9  # front, then back
    for part, value in facing["novelty"].items():
        assert away["novelty"][part] == pytest.approx(value, abs=1e-6), part
    # not the ~1.1 a global-pose vocabulary gave the main body of a mocap frame
    assert away["novelty"]["main_body"] < 0.5
    assert rep["overlay_colour_diff"] < 1e-6  # the overlay colours each vertex the same
    for run in (facing, away):  # the body is in view, drawn with the overlay
        assert silhouette(run["view"]["png"]).mean() > 0.02
