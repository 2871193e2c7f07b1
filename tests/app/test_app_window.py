"""The viewer window for real: a GLFW window under Xvfb, driven by the ImGui Test Engine
(app/testing/scripts.py). It moves a left-arm slider and clicks a vocabulary key the way a
user would; the vocabulary panel's keys and weights must follow, the screenshot must show
the body, and the app (and its neural render worker) must exit cleanly."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from tiny_runs import tiny_run
from window_runs import PYTHON, ROOT, run_window

from texvocab_viewer.neural.view import REST_LEVELS
from texvocab_viewer.testing.bench import DRAGS, drag_stats

pytestmark = pytest.mark.slow  # Xvfb windows


@pytest.fixture(scope="module")
def tiny_checkpoint(tmp_path_factory):
    """A 6-frame, 4-view 64² capture and a checkpoint after 2 steps of a tiny model (its
    vocabulary: 3 keys per part, K = 2; the field still near its body-SDF init)."""
    return tiny_run(
        tmp_path_factory.mktemp("viewer"),
        ([("walk", 4), ("arm_raise", 4)], 5),
        6,
        4,
        dict(hidden=32, sdf_layers=2, color_layers=1, pos_freqs=4),
        texture_size=64,
        num_keys=3,
        k=2,
        rays_per_batch=128,
        coarse_samples=8,
        fine_samples=4,
        checkpoint_every=10,
        eval_views=(1,),
    )


def test_left_arm_slider_drives_the_vocabulary_panel(tiny_checkpoint, tmp_path):
    seq_poses = np.zeros((4, 24, 3), np.float32)
    seq_poses[:, 18, 1] = np.radians([-10, -40, -70, -100])  # left elbow bends
    seq_trans = np.stack([np.zeros(4), np.zeros(4), np.linspace(0, 0.3, 4)], 1).astype(np.float32)
    np.savez(tmp_path / "seq.npz", poses=seq_poses, trans=seq_trans)
    proc, rep, shot = run_window(tiny_checkpoint, "slider", tmp_path, "--poses", str(tmp_path / "seq.npz"))
    assert proc.returncode == 0 and rep["ok"], (rep.get("error"), rep.get("engine_log"), proc.stderr[-2000:])
    assert "Traceback" not in proc.stderr

    # the slider moved the joint (left shoulder z, degrees) and bumped the pose version
    assert rep["left_shoulder_deg"] == pytest.approx([0.0, 0.0, -70.0], abs=0.5)
    assert rep["version_after"] > rep["version_before"]

    # the vocabulary panel redrew the left arm's keys/weights; the other parts did not move
    before, after = rep["before"]["keys"], rep["after"]["keys"]
    assert set(before) == set(after) == {"main_body", "left_leg", "right_leg", "left_arm", "right_arm"}
    assert before["left_arm"] != after["left_arm"]
    for part in ("main_body", "left_leg", "right_leg", "right_arm"):
        assert before[part] == after[part], part
    for part, keys in after.items():
        assert len(keys) == 2 and sum(w for _, _, w in keys) == pytest.approx(1.0), part
    assert rep["before"]["novelty"]["left_arm"] != rep["after"]["novelty"]["left_arm"]
    # the panel highlights the part the slider moved, and draws each key's distance as a
    # bar against the part's range: the nearest key's bar is the shortest
    assert rep["after"]["moved"] == ["left_arm"]
    bars = rep["after"]["distance_bars"]
    assert set(bars) == set(after)
    for part, keyed in bars.items():
        lengths = [b for _, b in keyed]
        assert [k for k, _ in keyed] == [k for k, _, _ in after[part]], part
        assert all(0.0 <= b <= 1.0 for b in lengths) and lengths == sorted(lengths), (part, lengths)
    assert bars["left_arm"][0][1] > 0  # moved off every key: a bar to see
    # the buttons of the newly selected keys exist in the panel
    assert set(rep["left_arm_buttons_found"]) == {str(k) for k, _, _ in after["left_arm"]}
    assert all(rep["left_arm_buttons_found"].values())

    # clicking a key moved the left arm onto that key: its nearest-key distance is ~0
    clicked = rep["after_click"]
    assert clicked["novelty"]["left_arm"] < 1e-6 < rep["after"]["novelty"]["left_arm"]
    assert rep["clicked_key"] in [k for k, _, _ in clicked["keys"]["left_arm"]]

    # the 3D view's camera: left drag orbits, the wheel zooms in, right drag pans, and
    # "Reset camera" faces the body again
    start, orbited = rep["camera_start"], rep["camera_orbited"]
    assert abs(orbited["yaw"] - start["yaw"]) > 5 and orbited["distance"] == start["distance"]
    assert rep["camera_zoomed"]["distance"] < orbited["distance"]
    panned = rep["camera_panned"]
    assert np.abs(np.subtract(panned["target"], rep["camera_zoomed"]["target"])).max() > 0.01
    assert rep["camera_reset"]["yaw"] == 0 and rep["camera_reset"]["pitch"] == 0

    # the pose file's timeline: loaded, scrubbed to frame 2, which is now the pose
    assert rep["sequence_error"] == "" and rep["sequence_frames"] == 4
    assert rep["sequence_frame"] == 2
    np.testing.assert_allclose(rep["pose_at_frame"], seq_poses[2], atol=1e-6)
    # the file's frame as the Root box's default (floor) stands it in the capture's world
    from texvocab.pipeline import load_avatar
    from texvocab_viewer.panels.pose import PoseSequence

    placed = PoseSequence.load(str(tmp_path / "seq.npz"), load_avatar(tiny_checkpoint).capture)
    np.testing.assert_allclose(rep["trans_at_frame"], placed.trans[2], atol=1e-6)
    np.testing.assert_allclose(np.diff(placed.trans[:, 2]), np.diff(seq_trans[:, 2]), atol=1e-6)
    # Play advances the timeline by wall time (30 fps) and the pose follows; Pause stops
    assert rep["played_to"] != 2 and rep["played_pose_matches"] and rep["paused"]

    # the neural render ran coarse to fine for the newest version, and its worker stopped
    neural = rep["neural"]
    assert neural["errors"] == [] and neural["level"] == 1
    # rendered over the 3D view's background (as texvocab shot and the screenshots are)
    assert neural["corner"] == pytest.approx([0.13, 0.14, 0.16], abs=1e-3)
    # the newest version is the pose the timeline rested at after playing: its full level
    # comes in one pass, after its preview only when that was not on screen yet
    last = max(v for v, _ in neural["delivered"])
    rested = [lv for v, lv in neural["delivered"] if v == last]
    assert rested[-1] == 1 and set(rested) <= set(REST_LEVELS), rested
    # every version shown was rendered coarse to fine: its levels never grow
    for version in {v for v, _ in neural["delivered"]}:
        shown = [lv for v, lv in neural["delivered"] if v == version]
        assert shown == sorted(shown, reverse=True), (version, shown)
    assert rep["worker_stopped"] is True
    # the UI idles while the render runs (each level wakes it), not while a sequence plays
    assert rep["idling_while_busy"] == [True] and rep["idling_when_done"] is True
    assert rep["idling_while_playing"] == [False]

    # the window's framebuffer is not multisampled (texvocab_viewer.window.WINDOW_MSAA_SAMPLES: under
    # llvmpipe a 4x buffer and its resolve cost ~20 ms of CPU a frame)
    assert rep["window_sample_buffers"] == 0

    # the screenshot is the whole window and shows the body in the 3D view, copied into
    # the window's framebuffer (app/gl/view_blit.py), not drawn by ImGui
    assert rep["view_blits"] > 0
    img = np.asarray(Image.open(shot).convert("RGB")).astype(np.float32)
    assert img.shape == (800, 1280, 3) and img.std() > 10
    x, y, w, h = (int(round(v)) for v in rep["view_rect"])
    assert w > 200 and h > 400
    bg = np.array((0.13, 0.14, 0.16)) * 255  # SceneOptions.background
    view = img[y : y + h, x : x + w]
    corner = view[h - 20 : h - 5, 5:20]
    assert np.abs(corner - bg).max() < 12, "the view's corner should be background"
    body = np.abs(view - bg).max(-1) > 30
    body[:40] = False  # the caption line drawn over the view
    assert 0.05 < body.mean() < 0.8, f"body covers {body.mean():.0%} of the 3D view"
    ys, xs = np.nonzero(body)
    assert ys.max() - ys.min() > 0.4 * h, "the body should fill much of the view's height"
    assert w * 0.25 < xs.mean() < w * 0.75 and h * 0.25 < ys.mean() < h * 0.75


@pytest.mark.parametrize("worker", ["process", "thread"])
def test_bench_run_renders_in_the_chosen_worker_and_the_window_idles_after(tiny_checkpoint, tmp_path, worker):
    """bench/viewer_ui.py's driver, short: three renders (the script's count) to full
    resolution in the render process (or thread), the CPU of each side measured, and after
    the last level the window idles again (a level's wake draws a frame, app/neural/wake.py)."""
    proc, rep, _ = run_window(
        tiny_checkpoint, "bench:1:64:3", tmp_path, "--neural-worker", worker, "--neural-preview-wait", "200"
    )
    assert proc.returncode == 0 and rep["ok"], (rep.get("error"), proc.stderr[-2000:])
    assert rep["neural_worker"] == worker and rep["errors"] == []
    assert (rep["render_pid"] != rep["window_pid"]) == (worker == "process")
    assert rep["blas_threads"] == 1  # texvocab/blas.py: no spinning OpenBLAS thread
    drag = rep["dragging"]
    assert len(drag["process_cpu_ms"]) == len(drag["frame_ms"])
    # the window process's CPU outside a render thread includes its UI thread's: per frame
    # with a render process; with a render thread, whose CPU is read in clock ticks
    # (/proc, 10 ms), over the whole drag, to two ticks
    pairs = [(p, c) for p, c in zip(drag["process_cpu_ms"], drag["cpu_ms"]) if p is not None]
    if worker == "process":
        assert all(p >= c - 0.5 for p, c in pairs)
    else:
        tick_ms = 1000 / os.sysconf("SC_CLK_TCK")
        assert sum(p for p, _ in pairs) >= sum(c for _, c in pairs) - 0.5 * len(pairs) - 2 * tick_ms
    assert len(rep["renders"]) == 3
    assert [r["pose"] for r in rep["renders"]] == ["walk", "squat", "walk"]
    for r in rep["renders"]:
        assert [lv["level"] for lv in r["levels"]][-1] == 1
        assert r["render_cpu_share"] > 0 and r["ui_cpu_share"] > 0
    # a pose frame after a pause waits for its preview (at most --neural-preview-wait
    # from the change, here 200 ms, far more than the tiny model's preview needs) and
    # shows it: the first level is on screen in the very frame that changed the pose.
    # (The first render's pose can be followed by a second submission of its own.)
    waited = [r for r in rep["renders"] if r["preview_wait"]]
    assert len(waited) >= 2, [r["preview_wait"] for r in rep["renders"]]
    assert all(r["preview_wait"][1] and 0 <= r["preview_wait"][0] < 200 for r in waited)
    assert all(r["levels"][0]["on_screen_s"] == r["pose_frame_s"] for r in waited)
    # those that came after ImGui drew the frame were drawn over it just before the swap
    # (as were other pauses' previews: the bench's resolution change, its dragging's start)
    assert rep["preview_blits"] >= sum(1 for r in waited if r["preview_wait"][0] > 0)
    # while the slider is dragged, each frame shows the preview of a recent pose and the
    # full level follows once the drag stops. How recent depends on the machine's load
    # (the render processes run at niceness +10: an idle machine shows about 90 % of the
    # frames a pose at most one frame old, the full suite's load 10-56 %), so what is
    # asserted is what load does not change: every image shown while dragging is a
    # preview alone (level > 1, RenderJob.preview_only), and the shown pose is no older
    # than its own job's time explains (no queue of stale poses behind it): a preview
    # that takes J frames shows a pose J frames old when it arrives and 2J when the next
    # one replaces it, so the median age is below 2J (+ 2 frames of hand-over)
    within, frames = drag_stats(rep)["drag_frames_within_1"]
    age = drag["preview_age_frames"]
    assert frames >= 8 and within >= 1, age
    assert drag["levels_shown"] and all(level > 1 for level in drag["levels_shown"]), drag["levels_shown"]
    job_frames = np.median(drag["level_ms"]) / np.median(drag["frame_ms"])
    assert np.median(age) <= 2 * job_frames + 2, (age, drag["level_ms"], drag["frame_ms"])
    # every drag's stop brought its pose's full level (one settle per drag)
    assert len(rep["after_drag_full_s"]) == DRAGS and None not in rep["after_drag_full_s"]
    # the levels' wakes leave the window idling
    assert rep["after_render"]["seconds"] >= 1.5 and rep["after_render"]["frames"] <= 6
    assert rep["idle"]["frames"] <= 4  # 1 s idle at 1 frame per second


@pytest.mark.parametrize(
    "cmd", [[PYTHON, "-m", "texvocab_viewer"], [str(Path(PYTHON).parent / "texvocab"), "view"]]
)
def test_viewer_without_display_says_what_to_do(cmd):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: no display"), proc.stderr
    assert "texvocab shot" in lines[0] and "xvfb-run" in lines[0]


def test_render_worker_bench_runs_all_workers(tiny_checkpoint):
    """bench/render_worker.py, short: the thread, one process and two processes render
    with and without the UI-like load, and the summary line gives each one's slowdown
    and what the split gains."""
    proc = subprocess.run(
        [PYTHON, "bench/render_worker.py", str(tiny_checkpoint), "--rounds", "1", "--res", "32"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    rows = [
        line
        for line in proc.stdout.splitlines()
        if line.startswith("| thread") or line.startswith("| process")
    ]
    assert len(rows) == 6 and all(" | 2 | " in row for row in rows), proc.stdout
    assert sum(row.startswith("| process x2 |") for row in rows) == 2
    last = proc.stdout.strip().splitlines()[-1]
    values = dict(kv.split("=") for kv in last.removeprefix("summary: ").split())
    assert set(values) == {"thread_slowdown", "process_slowdown", "process_x2_slowdown", "split_speedup"}
    assert all(float(v) > 0 for v in values.values())


def test_the_ui_waker_is_glfws_empty_event_of_the_loaded_library():
    """app/neural/wake.py posts an empty event through the very libglfw imgui_bundle loaded (one
    copy in the process), not hello_imgui.request_refresh."""
    from imgui_bundle import hello_imgui

    from texvocab_viewer.neural.wake import ui_waker

    wake = ui_waker()
    assert wake is not hello_imgui.request_refresh and wake.__name__ == "glfwPostEmptyEvent"
    maps = Path("/proc/self/maps").read_text()
    glfw = {line.split()[-1] for line in maps.splitlines() if "libglfw" in line}
    assert len(glfw) == 1, glfw
