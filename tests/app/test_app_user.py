"""The viewer as a new user meets it, in a real window (Xvfb, ImGui Test Engine): errors
in the status line with their whole text, a bad ``--poses`` file refused at once, a clean
close while a video exports, and the layout at small and large window sizes."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from tiny_runs import smallest_run
from window_runs import PYTHON, run_window

slow = pytest.mark.slow  # Xvfb windows


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    return smallest_run(tmp_path_factory.mktemp("user"))


def pose_file(path, frames: int):
    poses = np.zeros((frames, 24, 3), np.float32)
    poses[:, 18, 1] = np.radians(np.linspace(-10, -100, frames))
    np.savez(path, poses=poses, trans=np.zeros((frames, 3), np.float32), mocap_framerate=np.float32(30))
    return path


def ok(proc, rep):
    assert proc.returncode == 0 and rep["ok"], (rep.get("error"), rep.get("engine_log"), proc.stderr[-2000:])
    assert "Traceback" not in proc.stderr


@slow
def test_a_bad_pose_path_after_a_good_sequence_keeps_it_and_says_why(checkpoint, tmp_path):
    good, later = pose_file(tmp_path / "walk.npz", 12), pose_file(tmp_path / "later.npz", 5)
    bad = tmp_path / "notes.npz"
    bad.write_text("not a zip")
    missing = tmp_path / "no such folder" / "walk_typo.npz"
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    zenity = bin_dir / "zenity"  # File > Open pose file... picks notes.npz
    zenity.write_text(f'#!/bin/sh\ncase "$*" in *--version*) echo 3.44.0 ;; *) echo {bad} ;; esac\n')
    zenity.chmod(0o755)
    env = dict(
        os.environ,
        PATH=f"{bin_dir}:{os.environ['PATH']}",
        TEXVOCAB_TEST_MISSING_POSES=str(missing),
        TEXVOCAB_TEST_GOOD_POSES=str(later),
    )
    proc, rep, _ = run_window(checkpoint, "bad-pose", tmp_path, "--poses", str(good), env=env)
    ok(proc, rep)
    assert rep["start"] == {"path": str(good), "frames": 12}
    assert rep["open_at_start"]  # --poses opens the Sequence header
    # the menu's route: the error is in the status line, whole, and in its tooltip
    after = rep["after_dialog"]
    assert after["error"] and rep["kept_after_dialog"] and rep["timeline_shown"]
    assert after["text"].startswith("pose file not loaded (kept walk.npz): ")
    assert str(bad) in after["text"] and "not an .npz archive" in after["text"]
    assert after["drawn"] and after["text"].startswith(after["drawn"].removesuffix("..."))
    assert rep["tooltip"] == after["text"]
    assert rep["after_close"] == {"text": "", "error": False, "drawn": ""}  # its "x"
    # a typo in the path field: the sequence, Play and the timeline stay
    typo = rep["after_typo"]
    assert typo["error"] and rep["kept_after_typo"] and rep["play_shown"] and rep["timeline_shown_after"]
    assert str(missing) in typo["text"] and "not found" in typo["text"]
    # the next load that succeeds replaces an error
    assert rep["after_good"] == {
        "text": "loaded later.npz: 5 frames",
        "error": False,
        "drawn": "loaded later.npz: 5 frames",
    }
    assert rep["frames_after_good"] == 5


def test_a_bad_poses_file_is_refused_before_the_avatar_loads(tmp_path):
    bad = tmp_path / "notes.npz"
    bad.write_text("not a zip")
    # the source does not exist either: the pose file is checked first, with no display
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    proc = subprocess.run(
        [PYTHON, "-m", "texvocab_viewer", str(tmp_path / "missing.pt"), "--poses", str(bad)],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
    )
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: --poses {bad}: "), lines
    assert "not an .npz archive" in lines[0] and "preparing" not in proc.stdout


@slow
def test_closing_the_window_during_export_video_stops_it_and_removes_its_files(checkpoint, tmp_path):
    poses = pose_file(tmp_path / "walk.npz", 300)
    work, end = tmp_path / "work", tmp_path / "ended"
    work.mkdir()
    # the window's process, then the time it ended (xvfb-run's own teardown not counted)
    shell = f'"$0" -m texvocab_viewer "$@"; rc=$?; date +%s.%N > {end}; exit $rc'
    proc, rep, _ = run_window(
        checkpoint,
        "close-exporting",
        tmp_path,
        "--poses",
        str(poses),
        command=("sh", "-c", shell, PYTHON),
        cwd=work,
    )
    ok(proc, rep)
    assert rep["running_at_close"] and 2 <= rep["frames_before_close"] < rep["total"] == 300
    assert rep["closed_by_window"]  # the window's close request ended the run
    assert "terminate called" not in proc.stderr
    seconds = float(end.read_text()) - rep["closed_at"]
    assert seconds < 2.0, seconds
    assert sorted(p.name for p in (work / "exports").iterdir()) == []  # no partial video or frames


@slow
def test_the_timeline_says_pose_edited_since_on_its_own_line_in_a_narrow_window(checkpoint, tmp_path):
    from PIL import Image

    poses = pose_file(tmp_path / "walk.npz", 12)
    proc, rep, shot = run_window(
        checkpoint, "edited-narrow", tmp_path, "--poses", str(poses), size="480x320", screen="640x480"
    )
    ok(proc, rep)
    assert rep["note_before"] == ""  # the pose is the sequence's frame
    assert rep["note"] == "pose edited since frame 0"  # a slider moved it away
    # drawn wrapped on a line of its own, so the narrow panel cannot cut it off
    assert 0 < rep["note_width"] and rep["pose_width"] == 480
    assert np.asarray(Image.open(shot)).shape[:2] == (320, 480)


@slow
def test_closing_the_window_while_it_plays_and_renders_exits_at_once(checkpoint, tmp_path):
    poses = pose_file(tmp_path / "walk.npz", 300)
    end = tmp_path / "ended"
    shell = f'"$0" -m texvocab_viewer "$@"; rc=$?; date +%s.%N > {end}; exit $rc'
    proc, rep, _ = run_window(
        checkpoint, "close-playing", tmp_path, "--poses", str(poses), command=("sh", "-c", shell, PYTHON)
    )
    ok(proc, rep)
    assert rep["playing_at_close"] and rep["rendering_at_close"] and rep["closed_by_window"]
    seconds = float(end.read_text()) - rep["closed_at"]
    assert seconds < 2.0, seconds


@slow
@pytest.mark.parametrize(
    ("size", "kind"),
    [("480x320", "tabs"), ("640x400", "narrow"), ("900x600", "medium"), ("1920x1080", "wide")],
)
def test_the_panels_keep_a_usable_size_in_small_and_large_windows(checkpoint, tmp_path, size, kind):
    from PIL import Image

    from texvocab_viewer.layout import MIN_WIDTH

    proc, rep, shot = run_window(checkpoint, "layout", tmp_path, size=size, screen="1920x1200")
    ok(proc, rep)
    assert rep["layout"] == kind
    sizes = rep["sizes"]
    for name, floor in MIN_WIDTH.items():
        # every panel is drawn (a tab brought to the front), no narrower than its floor
        assert sizes[name]["drawn"] and sizes[name]["w"] >= floor - 2, (name, sizes[name])
        assert sizes[name]["h"] >= 200, (name, sizes[name])
    w, h = rep["view_size"]
    assert w >= 300 and h >= 170, rep["view_size"]  # the 3D view's image, under its toolbar
    assert rep["last_slider_reached"]  # the Pose panel scrolls to its last joint
    assert rep["relayouts"] == 0  # the layout it opened with stays
    if kind == "tabs":  # one column: the four panels as tabs, each the window's width
        assert len(set(rep["spaces"].values())) == 1
        assert all(sizes[name]["w"] == 480 for name in sizes), sizes
        assert rep["drawn_at_start"] == ["3D view"]  # the tab in front at start
    elif kind == "narrow":  # stacked: Pose and Vocabulary share a column as tabs
        assert rep["spaces"]["Pose"] == rep["spaces"]["Vocabulary"]
    else:
        assert len(set(rep["spaces"].values())) == 4
    image = np.asarray(Image.open(shot))
    assert image.shape[:2] == tuple(int(v) for v in size.split("x"))[::-1] and image.std() > 10


@slow
def test_a_resized_window_docks_its_panels_anew(checkpoint, tmp_path):
    from texvocab_viewer.layout import MIN_WIDTH

    proc, rep, _ = run_window(checkpoint, "resize", tmp_path, screen="1920x1200")
    ok(proc, rep)
    assert rep["start"] == "wide"  # 1280 x 800
    (small, large) = rep["steps"]
    assert small["size"] == [640, 400] and small["layout"] == "narrow"
    assert large["size"] == [1600, 1000] and large["layout"] == "wide"
    for step in (small, large):
        for name, floor in MIN_WIDTH.items():
            got = step["sizes"][name]
            assert got["drawn"] and got["w"] >= floor - 2, (step["size"], name, got)


def test_a_preset_sets_the_whole_pose_as_shot_does():
    """After a mocap frame that turned the body and moved it, a preset is the same pose as
    on a fresh state (what ``texvocab shot --pose NAME`` applies)."""
    from texvocab_viewer.state import ViewerState, load_viewer_data

    data = load_viewer_data(None)
    state = ViewerState(data)
    turned = np.zeros((24, 3))
    turned[0] = [0.0, np.radians(150.0), 0.2]
    state.set_pose(turned, [1.0, 0.3, -2.0])
    state.apply_preset("kick")
    shot = ViewerState(data)
    shot.apply_preset("kick")
    np.testing.assert_array_equal(state.pose, shot.pose)
    np.testing.assert_array_equal(state.trans, shot.trans)
    assert not np.allclose(state.pose[0], turned[0])


def test_exports_are_written_with_the_users_umask(tmp_path):
    from texvocab.pipeline import Camera
    from texvocab_viewer.export.job import Export

    cam = Camera(np.eye(3), np.eye(3), np.zeros(3), 8, 8)
    old = os.umask(0o027)
    try:
        job = Export(
            None,
            None,
            cam,
            np.zeros((1, 24, 3)),
            np.zeros((1, 3)),
            "shot",
            1.0,
            np.full((8, 8, 3), 9, np.uint8),
            folder=tmp_path / "exports",
        )
        job.thread.join(30)
    finally:
        os.umask(old)
    assert job.error == ""
    assert (job.path / "view3d.png").stat().st_mode & 0o777 == 0o640


def test_video_frames_and_screenshots_share_the_3d_views_background(tmp_path):
    """Export video renders each frame as Screenshot renders its one, over the 3D view's
    background colour (not black)."""
    import imageio_ffmpeg
    from PIL import Image

    from texvocab.pipeline import Camera, load_avatar, march_settings
    from texvocab_viewer.export.job import Export
    from texvocab_viewer.gl.scene import SceneOptions

    avatar = load_avatar(smallest_run(tmp_path / "run"))
    march = march_settings(avatar.settings)
    cam = Camera(
        np.array([[40.0, 0, 16], [0, 40.0, 16], [0, 0, 1]]), np.eye(3), np.array([0.0, 0.0, 3.0]), 32, 32
    )
    background = SceneOptions().background
    jobs = [
        Export(
            avatar.model,
            march,
            cam,
            np.zeros((n, 24, 3)),
            np.zeros((n, 3)),
            "walk",
            30.0,
            folder=tmp_path / "exports",
            background=background,
        )
        for n in (1, 3)
    ]
    for job in jobs:
        job.thread.join(120)
        assert job.error == "", job.error
    shot = np.asarray(Image.open(jobs[0].path / "neural.png").convert("RGB"), np.int16)
    reader = imageio_ffmpeg.read_frames(str(jobs[1].path))
    meta = next(reader)
    frame = np.frombuffer(next(reader), np.uint8).reshape(meta["size"][1], meta["size"][0], 3)
    expected = np.round(np.asarray(background) * 255)
    np.testing.assert_allclose(shot[0, 0], expected, atol=1)
    np.testing.assert_allclose(frame[0, 0], expected, atol=4)  # H.264's rounding


def test_the_layout_gives_each_column_its_floor_at_every_width():
    from texvocab_viewer.layout import MAIN, MIN_WIDTH, NARROW, layout_for

    for width in range(320, 2600, 20):
        for model in (True, False):
            lay = layout_for(width, 700, model)
            if lay.kind == "tabs":  # one column: every panel a tab, the window's width
                assert width < NARROW and lay.splits == () and set(lay.spaces.values()) == {MAIN}
                assert width >= max(MIN_WIDTH.values())
                continue
            left = right = 0.0
            rest = float(width)
            for s in lay.splits:  # the pixels each split takes from the main space
                if s.side == "down":
                    continue
                px = s.ratio * rest
                rest -= px
                left, right = (left + px, right) if s.side == "left" else (left, right + px)
            spaces = lay.spaces
            assert set(spaces) == set(MIN_WIDTH)
            pose_col = left
            assert pose_col >= MIN_WIDTH["Pose"] - 1
            if spaces["Vocabulary"] == spaces["Pose"]:
                assert lay.kind == "narrow" and pose_col >= MIN_WIDTH["Vocabulary"] - 1
            else:
                assert right >= MIN_WIDTH["Vocabulary"] - 1
            assert rest >= MIN_WIDTH["3D view"] - 1, (width, model, rest)
    # at 1280 x 800 the four columns are as they always were: 22 % and 30 % of the rest
    wide = layout_for(1280, 800, True)
    assert wide.kind == "wide" and [round(s.ratio, 3) for s in wide.splits] == [0.22, 0.3, 0.5]
    assert layout_for(640, 400, True).spaces["Neural render"] == MAIN  # a tab beside the 3D view
    assert layout_for(640, 700, True).spaces["Neural render"] == "NeuralSpace"  # under it


def test_the_status_line_cuts_a_long_message_to_its_width():
    from texvocab_viewer.status import fit_text

    def measure(s):
        return 7.0 * len(s)  # 7 px a character

    assert fit_text("loaded walk.npz: 9 frames", 700, measure) == "loaded walk.npz: 9 frames"
    long = "could not open /tmp/a/very/long/path/fake.pt: not a checkpoint"
    cut = fit_text(long, 140, measure)
    assert cut.endswith("...") and long.startswith(cut[:-3]) and measure(cut) <= 140
    assert len(cut) == 20  # the longest start that fits with "..."
    assert fit_text("first line\nsecond", 700, measure) == "first line..."


def test_the_stale_banner_says_what_changed_and_its_tooltip_what_it_shows():
    from texvocab_viewer.neural.view import NeuralView
    from texvocab_viewer.neural.worker import RenderFrame
    from texvocab_viewer.panels.neural import banner_text
    from texvocab_viewer.state import load_viewer_data
    from texvocab_viewer.viewer import Viewer

    class Worker:
        busy, delivered, errors = False, [], []

        def submit(self, job):
            pass

        def poll(self):
            return None

    v = Viewer(load_viewer_data(None))
    nv = NeuralView(None, None, None, worker=Worker())
    nv.update(v.state, v.camera, 1.0, label="rest pose")
    nv.frame = RenderFrame(nv.version, 1, np.zeros((8, 8, 3), np.float32), 0.1, 0.1)  # shown
    assert nv.stale_reason() == "" and nv.stale_tooltip() == ""
    v.state.set_joint(16, (0.0, 0.0, -70.0))
    nv.update(v.state, v.camera, 1.0, label=v.pose_label())
    assert nv.stale_reason() == "pose edited since"
    line = nv.stale_line()
    assert line == "stale: shows rest pose; rendering left shoulder z -70°"
    assert nv.stale_tooltip() == f"{line}\nshown: rest pose\ncurrent: left shoulder z -70°"
    nv.frame = RenderFrame(nv.version, 1, np.zeros((8, 8, 3), np.float32), 0.1, 0.1)
    v.camera.orbit(30.0, 0.0)  # the camera alone
    nv.update(v.state, v.camera, 1.0, label=v.pose_label())
    assert nv.stale_reason() == "camera moved since"

    def measure(s):
        return 7.0 * len(s)

    wide = banner_text("pose edited since", line, 600, measure)
    assert wide == "stale, pose edited since: shows rest pose; rendering left shoulder z -70°"
    assert banner_text("pose edited since", line, 300, measure) == "stale, pose edited since"
    cut = banner_text("pose edited since", line, 120, measure)
    assert cut.endswith("...") and measure(cut) <= 120 - 12 and cut.startswith("stale, ")
    assert banner_text("pose edited since", "", 600, measure) == ""


def test_the_vocabulary_panel_knows_the_moved_parts_and_each_keys_range(tmp_path):
    from texvocab_viewer.panels.vocab import distance_bar
    from texvocab_viewer.state import ViewerState, load_viewer_data

    # a global-pose vocabulary; copied, since loading caches texture maps into the capture
    saved = tmp_path / "checkpoint_main"
    shutil.copytree(Path(__file__).parent.parent / "data" / "checkpoint_main", saved)
    data = load_viewer_data(str(saved / "checkpoint.pt"), capture=str(saved / "capture"))
    state = ViewerState(data)
    state.set_joint(16, (0.0, 0.0, -70.0))  # the left shoulder
    assert state.moved_parts() == ["left_arm"]
    state.set_joint(5, (30.0, 0.0, 0.0))  # the right knee
    assert state.moved_parts() == ["right_leg"]
    turned = state.pose.copy()
    turned[0] = [0.0, 1.0, 0.0]  # the root alone
    state.set_pose(turned)
    assert state.moved_parts() == ["main_body"]  # its vocabulary sees the root
    data.vocab.pose_condition = "root-relative"  # one that does not
    state.set_pose(state.pose * 0.5)
    state.set_joint(0, (0.0, 20.0, 0.0))
    assert 0 in data.vocab.ignored_joints and state.moved_parts() == []
    for q, all_keys in zip(state.query(), state.key_distances(), strict=True):
        # the selected keys are the nearest of all the part's keys (Eq. 4, the same distances)
        np.testing.assert_allclose(np.sort(all_keys)[: len(q.distances)], q.distances, atol=1e-9)
    assert distance_bar(0.2, 0.8) == 0.25 and distance_bar(0.0, 0.0) == 0.0 and distance_bar(2.0, 1.0) == 1.0
