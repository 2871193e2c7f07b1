"""The viewer as a daily tool, in a real window (Xvfb, ImGui Test Engine): a stale render
says so, capture cameras as presets give what ``texvocab shot --camera N`` gives,
sequences start from ``--poses`` and play at their file's rate, the native file dialog
loads a pose file, follow keeps the camera on the root, and the weights panel's numbers."""

from __future__ import annotations

import os
import stat
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from tiny_runs import smallest_run
from window_runs import PYTHON, run_window

pytestmark = pytest.mark.slow  # Xvfb windows

TEXVOCAB = str(Path(PYTHON).parent / "texvocab")


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    return smallest_run(tmp_path_factory.mktemp("daily"))


def walk_file(path: Path, frames: int, fps: float | None) -> Path:
    """An SMPL pose file: the left elbow bends and the root moves 0.5 m along +x."""
    poses = np.zeros((frames, 24, 3), np.float32)
    poses[:, 18, 1] = np.radians(np.linspace(-10, -100, frames))
    trans = np.zeros((frames, 3), np.float32)
    trans[:, 0] = np.linspace(0.0, 0.5, frames)
    extra = {} if fps is None else {"mocap_framerate": np.float32(fps)}
    np.savez(path, poses=poses, trans=trans, **extra)
    return path


def fake_zenity(tmp_path: Path, answer: Path) -> tuple[dict, Path]:
    """The desktop's dialog program, played by a script on PATH that answers ``answer``
    (portable-file-dialogs runs it for real); (environment, its argument log)."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    log = tmp_path / "zenity.log"
    fake = bin_dir / "zenity"
    fake.write_text(
        f'#!/bin/sh\necho "$@" >> {log}\ncase "$*" in *--version*) echo 3.44.0 ;; *) echo {answer} ;; esac\n'
    )
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    return dict(os.environ, PATH=f"{bin_dir}:{os.environ['PATH']}"), log


def ok(proc, rep):
    assert proc.returncode == 0 and rep["ok"], (rep.get("error"), rep.get("engine_log"), proc.stderr[-2000:])
    assert "Traceback" not in proc.stderr


def test_a_changed_pose_marks_the_shown_render_stale_until_its_first_level(checkpoint, tmp_path):
    # the frame that changes the pose does not wait for the preview here, so the old
    # image is shown stale for at least that frame (with the wait, the preview usually
    # comes in that frame and nothing is ever stale: test_app_window's bench run)
    proc, rep, _ = run_window(checkpoint, "stale", tmp_path, "--neural-preview-wait", "0")
    ok(proc, rep)
    assert rep["change"] == "left shoulder z -70°"
    lines = rep["stale_lines"]
    expected = "stale: shows rest pose; rendering left shoulder z -70°"
    assert expected in lines, lines[:20]
    # the banner came first, then the first new level replaced the image (no banner after)
    first = lines.index(expected)
    assert "" in lines[first:] and lines[-1] == "" and rep["stale_at_end"] is False
    assert rep["neural"]["level"] == 1 and rep["neural"]["errors"] == []
    # with Live off nothing new renders: the image stays marked, and the banner says why
    assert rep["live_off_line"] == ("stale: shows left shoulder z -70°; Live is off (Render now)")
    # the banner says the pose was edited since (the whole line does not fit the image's
    # width in a 1280-wide window); hovering the image gives the whole text
    assert rep["live_off_banner"] == "stale, pose edited since"
    assert rep["live_off_tooltip"] == (
        "stale: shows left shoulder z -70°; Live is off (Render now)\n"
        "shown: left shoulder z -70°\ncurrent: left shoulder z -40°"
    )


def test_capture_camera_preset_matches_shot_camera_n(checkpoint, tmp_path):
    poses = walk_file(tmp_path / "walk.npz", 5, None)
    work = tmp_path / "work"
    work.mkdir()
    proc, rep, _ = run_window(checkpoint, "camera-view", tmp_path, "--poses", str(poses), cwd=work)
    ok(proc, rep)
    assert rep["camera_index"] == 1
    shot = rep["shot_export"]
    assert not shot["error"] and shot["path"].endswith("exports/shot")
    assert rep["f12_export"]["path"].endswith("exports/shot_2")  # F12: the same, no overwrite
    assert (work / "exports" / "shot_2" / "neural.png").is_file()
    proc_shot = subprocess.run(
        [
            TEXVOCAB,
            "shot",
            str(checkpoint),
            "--pose",
            f"{poses}:0",
            "--camera",
            "1",
            "--out",
            str(tmp_path / "cli"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc_shot.returncode == 0, proc_shot.stderr
    for name in ("view3d.png", "neural.png"):
        window = np.asarray(Image.open(work / "exports" / "shot" / name).convert("RGB"), np.int16)
        cli = np.asarray(Image.open(tmp_path / "cli" / name).convert("RGB"), np.int16)
        assert window.shape == cli.shape == (64, 64, 3), name  # the camera's own size
        diff = np.abs(window - cli).max(-1)
        # same camera, pose and renderer: equal up to one 8-bit level (GL: the window's
        # GLX llvmpipe against shot's OSMesa llvmpipe; neural: thread count)
        assert diff.max() <= 1, (name, int(diff.max()), float((diff > 0).mean()))
        assert cli.std() > 5, name
    # follow: the camera moved with the root (0.5 m along +x over the sequence)
    np.testing.assert_allclose(rep["camera_moved"], rep["root_moved"], atol=1e-6)
    assert rep["root_moved"][0] > 0.4
    # a drag leaves the preset for the nearest orbit camera
    assert rep["after_drag"] == "OrbitCamera"


def test_texvocab_view_starts_on_poses_and_plays_at_the_files_rate(checkpoint, tmp_path):
    poses = walk_file(tmp_path / "walk.npz", 200, 20.0)
    proc, rep, shot = run_window(
        checkpoint, "playback", tmp_path, "--poses", str(poses), command=(TEXVOCAB, "view")
    )
    ok(proc, rep)
    assert rep["start_pose_matches"] is True  # --poses: frame 0 shown at start
    assert rep["fps"] == 20.0 and rep["file_fps"] == 20.0
    rate = rep["played_frames"] / rep["played_seconds"]
    assert 16.0 < rate < 22.0, rep
    # the neural render followed the timeline (several frames shown while playing)
    assert rep["versions_shown_while_playing"] >= 2, rep
    assert rep["timeline_left_after_reset"] is True
    assert rep["idling_while_playing"] == [False]
    assert np.asarray(Image.open(shot)).std() > 10


def test_open_dialog_loads_the_chosen_pose_file(checkpoint, tmp_path):
    poses = walk_file(tmp_path / "walk.npz", 7, 30.0)
    env, log = fake_zenity(tmp_path, poses)  # the dialog picks walk.npz
    proc, rep, _ = run_window(checkpoint, "open-dialog", tmp_path, env=env)
    ok(proc, rep)
    assert rep["dialog_missing"] == ""
    assert rep["sequence_path"] == str(poses) and rep["sequence_frames"] == 7
    assert "--file-selection" in log.read_text()


def test_file_open_checkpoint_loads_it_and_reopens_the_window(checkpoint, tmp_path):
    env, _ = fake_zenity(tmp_path, checkpoint)
    poses = walk_file(tmp_path / "walk.npz", 6, 30.0)
    # the body alone with a pose sequence; File > Open checkpoint...; the window reopens
    proc, rep, _ = run_window(None, "open-checkpoint", tmp_path, "--poses", str(poses), env=env)
    ok(proc, rep)
    assert rep["script"] == "reopened"  # the report of the second window
    assert rep["source"].startswith(f"checkpoint {checkpoint}") and rep["has_neural"] is True
    assert rep["sequence_path"] == str(poses) and rep["sequence_frames"] == 6  # kept


def test_file_open_of_a_bad_file_says_why_and_keeps_the_window(tmp_path):
    bad = tmp_path / "notes.pt"
    bad.write_text("not a checkpoint")
    env, _ = fake_zenity(tmp_path, bad)
    proc, rep, _ = run_window(None, "open-checkpoint", tmp_path, env=env)
    ok(proc, rep)
    assert rep["script"] == "open-checkpoint"  # no second window
    assert rep["open_error"].startswith(f"{bad}:") and rep["exit_requested"] is False
    assert rep["status"]["error"] and rep["status"]["text"].startswith(f"could not open {bad}:")


def test_no_dialog_program_is_said_not_hidden(monkeypatch):
    from texvocab_viewer.dialogs import FileDialogs

    monkeypatch.setenv("PATH", "/nonexistent")
    assert "zenity" in FileDialogs.missing()


def test_weights_panel_shows_distance_raw_weight_and_share():
    from texvocab_viewer.panels.vocab import key_caption, raw_weight

    assert raw_weight("paper", 3, 0.25) == pytest.approx(2.75)
    assert raw_weight("inverse", 3, 0.25) == pytest.approx(4.0)
    assert raw_weight("inverse", 3, 0.0) == float("inf")
    assert key_caption("paper", 3, 0.0123, 0.334, 3) == "d 0.0123  w 2.988  33.4% (+0.1)"
    assert key_caption("inverse", 3, 0.0, 1.0, 3).startswith("d 0.0000  w exact  100.0%")


def test_follow_centres_the_root_in_an_orbit_view_and_keeps_it_there():
    from texvocab_viewer.state import load_viewer_data
    from texvocab_viewer.viewer import Viewer

    v = Viewer(load_viewer_data(None))  # no window needed: follow is camera arithmetic
    v.camera.target = np.array([0.3, -0.2, 0.1])
    root = v.root_position()
    v.set_follow(True)
    # centred horizontally on the root, the view's height offset kept
    np.testing.assert_allclose(v.camera.target, [root[0], -0.2, root[2]])
    v.state.set_trans([0.5, 0.1, -0.4])
    v.follow_root()
    moved = v.root_position()
    np.testing.assert_allclose(v.camera.target, [moved[0], -0.2 + moved[1] - root[1], moved[2]], atol=1e-9)
    v.set_follow(False)
    v.state.set_trans([0.0, 0.0, 0.0])
    v.follow_root()
    np.testing.assert_allclose(v.camera.target[0], moved[0])  # off: the camera stays


def test_export_video_follows_the_root_when_follow_is_on():
    from texvocab.pipeline import Camera
    from texvocab_viewer.viewer import follow_cameras

    cam = Camera(
        np.array([[100.0, 0, 32], [0, 100.0, 32], [0, 0, 1]]), np.eye(3), np.array([0.0, 0.0, 3.0]), 64, 64
    )
    trans = np.array([[0.0, 0, 0], [0.3, 0, 0], [0.6, 0.1, 0]])
    cams = follow_cameras(cam, trans, now=trans[1])
    for c, t in zip(cams, trans, strict=True):
        np.testing.assert_allclose(c.center - cam.center, t - trans[1], atol=1e-12)
        np.testing.assert_array_equal(c.R, cam.R)
        # the root's rest position plus t lands on the same pixel in every frame
        root = np.array([0.0, -0.2, 0.0])
        px, _ = c.project((root + t)[None])
        ref, _ = cam.project((root + trans[1])[None])
        np.testing.assert_allclose(px, ref, atol=1e-9)


def test_screenshot_without_a_model_writes_the_3d_view_alone(tmp_path):
    from texvocab.pipeline import Camera
    from texvocab_viewer.export.job import Export

    cam = Camera(np.eye(3), np.eye(3), np.zeros(3), 8, 8)
    view = np.full((8, 8, 3), 200, np.uint8)
    job = Export(
        None,
        None,
        cam,
        np.zeros((1, 24, 3)),
        np.zeros((1, 3)),
        "shot",
        1.0,
        view,
        folder=tmp_path / "exports",
    )
    job.thread.join(30)
    assert job.error == "" and job.path == tmp_path / "exports" / "shot"
    assert sorted(p.name for p in job.path.iterdir()) == ["view3d.png"]


@pytest.mark.parametrize("script", ["look-stale", "look-views", "look-playback", "look-bad-pose"])
def test_screenshot_scripts_end_in_their_state(checkpoint, tmp_path, script):
    """The look-* scripts that produce the README's and the viewer page's window
    screenshots still run, and end in their state."""
    poses = walk_file(tmp_path / "walk.npz", 12, 30.0)
    env = dict(os.environ, TEXVOCAB_TEST_MISSING_POSES=str(tmp_path / "walk_typo.npz"))
    proc, rep, shot = run_window(checkpoint, script, tmp_path, "--poses", str(poses), env=env)
    ok(proc, rep)
    assert np.asarray(Image.open(shot)).std() > 10
    if script == "look-stale":
        assert rep["stale_line"].startswith("stale: shows frame 0; rendering left shoulder")
    if script == "look-bad-pose":
        assert rep["status"]["error"] and "walk_typo.npz" in rep["status"]["text"]
        assert rep["kept"] == 12


def test_dialog_program_search_follows_path(monkeypatch, tmp_path):
    """The per-frame check is cached per PATH value: a dialog program that appears on a
    new PATH is found, and the empty PATH still says none."""
    from texvocab_viewer.dialogs import FileDialogs

    program = tmp_path / "zenity"
    program.write_text("#!/bin/sh\n")
    program.chmod(0o755)
    monkeypatch.setenv("PATH", "/nonexistent")
    assert "zenity" in FileDialogs.missing()
    monkeypatch.setenv("PATH", str(tmp_path))
    assert FileDialogs.missing() == ""
    monkeypatch.setenv("PATH", "/nonexistent")
    assert "zenity" in FileDialogs.missing()


def test_a_pose_panel_edit_is_submitted_before_the_3d_view_draws():
    """The Pose panel's slider changes the pose mid-frame: the neural job goes out right
    after that panel (Viewer.SUBMIT_AFTER), not when the Neural render panel draws after
    the 3D view's work; only the frame's start polls levels."""
    from texvocab_viewer.neural.view import NeuralView
    from texvocab_viewer.state import load_viewer_data
    from texvocab_viewer.viewer import Viewer

    class Recorder:
        busy, delivered, errors = False, [], []

        def __init__(self):
            self.jobs, self.polls = [], 0

        def submit(self, job):
            self.jobs.append(job)

        def poll(self):
            self.polls += 1

    v = Viewer(load_viewer_data(None))
    worker = Recorder()
    v.neural = NeuralView(None, None, None, worker=worker)
    v.submit_neural()  # what Viewer.pre_new_frame does at a frame's start
    assert len(worker.jobs) == 1 and worker.polls == 1
    seen = []
    v.draw_panel("Pose", lambda viewer: viewer.state.set_joint(16, (0.0, 0.0, -40.0)))
    v.draw_panel("3D view", lambda viewer: seen.append(len(worker.jobs)))
    assert seen == [2], "the edited pose was not submitted before the 3D view drew"
    np.testing.assert_allclose(worker.jobs[-1].pose[16], np.radians([0.0, 0.0, -40.0]), atol=1e-6)
    assert worker.polls == 1  # a level is not uploaded mid-frame
    v.draw_panel("Vocabulary", lambda viewer: viewer.state.set_joint(17, (0.0, 0.0, 40.0)))
    assert len(worker.jobs) == 2  # other panels' edits go out at the next frame's start


def test_the_pose_frame_waits_for_the_preview_only_after_a_pause(monkeypatch):
    """NeuralView.wait_preview (Viewer.before_swap, after ImGui drew the frame): a pose
    submitted after a pause makes its frame wait for that job's first level, at most
    ``preview_wait`` from the submission, and take it; poses streaming in (a dragged
    slider) are previews alone, each frame waiting for its own until it must end
    (Viewer.drag_until), and the first frame without a change submits the resting pose's
    full render; no frame waits with ``preview_wait`` 0, for a preview that came while
    the frame was built (late_poll took it) or after a cancelled wait (a popup)."""
    import texvocab_viewer.neural.view as pn
    from texvocab_viewer.arguments import DRAG_FRAME_MS
    from texvocab_viewer.neural.view import NeuralView
    from texvocab_viewer.neural.worker import RenderFrame
    from texvocab_viewer.state import load_viewer_data
    from texvocab_viewer.viewer import Viewer

    class Texture:
        def __init__(self, size):
            self.size, self.written = size, 0

        def write(self, data):
            self.written += 1

    class Context:
        LINEAR = 0

        def texture(self, size, components):
            return Texture(size)

    class Waiter:
        busy, delivered, errors = True, [], []

        def __init__(self):
            self.jobs, self.waits, self.frame = [], [], None

        def submit(self, job):
            self.jobs.append(job)

        def poll(self):
            frame, self.frame = self.frame, None
            return frame

        def wait_for(self, version, timeout):
            self.waits.append((version, timeout))
            self.frame = RenderFrame(version, 8, np.zeros((4, 6, 3), np.float32), 0.01, 0.01)
            return True

    clock = [100.0]
    monkeypatch.setattr(pn.time, "perf_counter", lambda: clock[0])
    v = Viewer(load_viewer_data(None))
    worker = Waiter()
    v.neural = nv = NeuralView(Context(), None, None, worker=worker)
    nv.preview_wait = 0.03
    v.submit_neural()  # the first pose: after a pause
    nv.late_poll()  # before ImGui draws: nothing has come yet
    assert nv.awaiting and nv.frame is None
    assert nv.wait_preview()  # before the swap: waits, then takes the preview
    assert worker.waits == [(nv.version, pytest.approx(0.03))]
    assert nv.frame.version == nv.version and nv.texture.size == (6, 4)  # shown this frame
    assert nv.waits[-1][0] == nv.version and nv.waits[-1][2] and not nv.awaiting
    assert not worker.jobs[-1].preview_only and worker.jobs[-1].finish_preview
    for step in range(3):  # a dragged slider: a pose every 20 ms, its preview alone
        clock[0] += 0.02
        started = clock[0]  # the frame's start
        v.state.set_joint(16, (0.0, 0.0, -10.0 * (step + 1)))
        v.submit_neural()
        clock[0] += 0.005  # the panels
        nv.late_poll()
        assert nv.awaiting and nv.wait_preview(started + DRAG_FRAME_MS / 1000)
        assert worker.waits[-1] == (nv.version, pytest.approx(DRAG_FRAME_MS / 1000 - 0.005))
        assert worker.jobs[-1].preview_only and nv.frame.version == nv.version
    assert len(worker.waits) == 4 and len(worker.jobs) == 4
    nv.late_poll()  # a frame that changes nothing: the resting pose's full render
    rest = worker.jobs[-1]
    assert len(worker.jobs) == 5 and rest.version == nv.version and not nv.awaiting
    assert not rest.preview_only and not rest.finish_preview
    assert rest.levels == (1,)  # its preview is on screen: the full level at once
    np.testing.assert_array_equal(rest.pose, worker.jobs[-2].pose)
    assert nv.keys[nv.version] == nv.keys[nv.version - 1]
    nv.late_poll()
    assert len(worker.jobs) == 5  # once
    clock[0] += 0.3  # the slider rests, then moves again
    v.state.set_joint(16, (0.0, 0.0, 20.0))
    v.submit_neural()
    clock[0] += 0.01  # the frame's panels took 10 ms: 20 ms of the wait are left
    assert nv.awaiting and nv.wait_preview()
    assert worker.waits[-1] == (nv.version, pytest.approx(0.02))
    assert not nv.wait_preview()  # the next frame does not wait again
    assert len(worker.waits) == 5
    clock[0] += 1.0  # a preview that comes while the frame is built: no wait, counted
    v.state.set_joint(16, (0.0, 0.0, 25.0))
    v.submit_neural()
    worker.frame = RenderFrame(nv.version, 8, np.zeros((4, 6, 3), np.float32), 0.01, 0.01)
    nv.late_poll()
    assert not nv.awaiting and not nv.wait_preview()
    assert len(worker.waits) == 5 and nv.waits[-1] == (nv.version, 0.0, True)
    clock[0] += 1.0  # a popup could lie over the image: the frame does not wait
    v.state.set_joint(16, (0.0, 0.0, 27.0))
    v.submit_neural()
    nv.cancel_wait()
    assert not nv.awaiting and not nv.wait_preview() and len(worker.waits) == 5
    nv.preview_wait = 0.0
    clock[0] += 1.0
    v.state.set_joint(16, (0.0, 0.0, 30.0))
    v.submit_neural()
    assert not nv.awaiting and not nv.wait_preview()
    assert len(worker.waits) == 5 and len(worker.jobs) == 9
    for z in (32.0, 34.0):  # a drag whose last preview is not on screen yet when it rests
        clock[0] += 0.02
        v.state.set_joint(16, (0.0, 0.0, z))
        v.submit_neural()
        nv.late_poll()
    assert worker.jobs[-1].preview_only and nv.frame.version < nv.version
    nv.late_poll()
    assert worker.jobs[-1].levels == pn.REST_LEVELS and not worker.jobs[-1].preview_only
    nv.rest_levels = (8, 4, 2, 1)  # or the levels a caller names (bench/viewer_ui.py --rest-levels)
    clock[0] += 0.02
    v.state.set_joint(16, (0.0, 0.0, 36.0))
    v.submit_neural()
    nv.late_poll()
    nv.late_poll()
    assert worker.jobs[-1].levels == (8, 4, 2, 1)


def test_the_preview_blit_rectangles():
    """texvocab_viewer.gl.view_blit.image_rects: the whole texture, its row 0 (the image's top) to the
    rectangle's top in the window's bottom-up rows, scaled for HiDPI; nothing when the
    rectangle is empty or leaves the window."""
    from texvocab_viewer.gl.view_blit import image_rects

    src, dst = image_rects((10.0, 20.0, 110.0, 70.0), (32, 17), (1280, 800))
    assert src == (0, 0, 32, 17) and dst == (10, 780, 110, 730)  # flipped: y0 > y1
    assert image_rects((10.0, 20.0, 110.0, 70.0), (32, 17), (2560, 1600), (2.0, 2.0))[1] == (
        20,
        1560,
        220,
        1460,
    )
    assert image_rects((10.0, 20.0, 10.0, 70.0), (32, 17), (1280, 800)) is None
    assert image_rects((1200.0, 20.0, 1300.0, 70.0), (32, 17), (1280, 800)) is None
    assert image_rects((10.0, 780.0, 110.0, 810.0), (32, 17), (1280, 800)) is None


def test_a_dragged_frame_ends_its_wait_before_its_swap_would_pass_33_ms():
    """Viewer.drag_until: a dragged frame waits for its preview until DRAG_FRAME_MS after
    the frame began, less what recent frames took after their wait (the swap, input)."""
    from texvocab_viewer.arguments import DRAG_FRAME_MS
    from texvocab_viewer.state import load_viewer_data
    from texvocab_viewer.viewer import Viewer

    v = Viewer(load_viewer_data(None))
    v._last_frame = (50.0, 0.0)  # the frame began at perf_counter 50 s
    assert v.drag_until() == pytest.approx(50.0 + DRAG_FRAME_MS / 1000 - 0.004)
    v.wait_tails.extend([0.002] * 32)
    assert v.drag_until() == pytest.approx(50.0 + DRAG_FRAME_MS / 1000 - 0.002)
    v.wait_tails.extend([0.009] * 8)  # slower swaps: the wait ends earlier
    assert v.drag_until() == pytest.approx(50.0 + DRAG_FRAME_MS / 1000 - 0.009)
    assert DRAG_FRAME_MS < 33
