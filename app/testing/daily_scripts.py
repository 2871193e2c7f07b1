"""Scripted runs of the viewer as a daily tool (ImGui Test Engine, as app/testing/scripts.py):
stale renders, capture-camera presets and follow, playback, the File menu's dialogs and
its reopen, and ``look-*`` scripts that end in a state worth a screenshot."""

from __future__ import annotations

import os
import time

import numpy as np
from imgui_bundle import hello_imgui, imgui

from texvocab_viewer.testing.steps import LEFT_ARM_MOVE, wait_export, wait_neural


def script_stale(ctx, viewer, report: dict) -> None:
    """Full render, then a slider move: until the new pose's first level arrives, the
    shown render must be dimmed and labelled with the pose it shows."""
    ctx.yield_(6)
    wait_neural(ctx, viewer, report)
    viewer.stale_log.clear()
    ctx.set_ref("Pose")
    ctx.item_input_value(*LEFT_ARM_MOVE)
    report["change"] = viewer.state.change
    wait_neural(ctx, viewer, report)
    report["stale_lines"] = list(viewer.stale_log)
    report["stale_at_end"] = bool(viewer.neural.stale)
    ctx.set_ref("Neural render")
    ctx.item_click("**/Live")  # off: a new pose leaves the image stale, and it says why
    ctx.set_ref("Pose")
    ctx.item_input_value("**/left_shoulder/##z", -40.0)
    ctx.yield_(3)
    report["live_off_line"] = viewer.neural_stale_shown
    report["live_off_banner"] = viewer.neural_banner_drawn
    ctx.set_ref("Neural render")
    ctx.mouse_move("**/##image")  # the stale image hovered: the banner's whole text
    ctx.yield_(3)
    report["live_off_tooltip"] = viewer.neural_tooltip


def script_camera_view(ctx, viewer, report: dict) -> None:
    """Capture view 1 from the camera combo, Screenshot, Follow while the sequence moves
    the root, then a drag that leaves the preset for the nearest orbit camera."""
    ctx.yield_(4)
    ctx.set_ref("3D view")
    ctx.combo_click("##camera/capture view 1")  # a "**" wildcard misses "##" labels
    ctx.yield_(2)
    report["camera_index"] = getattr(viewer.camera, "index", None)
    ctx.item_click("**/Screenshot")
    report["shot_export"] = wait_export(ctx, viewer)
    ctx.mouse_move("**/##viewport")
    ctx.key_press(imgui.Key.f12)
    report["f12_export"] = wait_export(ctx, viewer)
    ctx.item_click("**/Follow")
    root0, shift0 = viewer.root_position(), viewer.camera.shift.copy()
    ctx.set_ref("Pose")
    ctx.item_open("**/Sequence")
    ctx.item_input_value("**/Sequence/##frame", len(viewer.sequence.poses) - 1)
    ctx.yield_(2)
    report["root_moved"] = (viewer.root_position() - root0).tolist()
    report["camera_moved"] = (viewer.camera.shift - shift0).tolist()
    ctx.set_ref("3D view")
    ctx.mouse_move("**/##viewport")
    ctx.mouse_drag_with_delta(imgui.ImVec2(40, 0))
    report["after_drag"] = type(viewer.camera).__name__


def script_playback(ctx, viewer, report: dict) -> None:
    """The --poses sequence at start, Play for ~2.5 s at the file's rate, Pause; Reset all
    then leaves the timeline (it says the pose was edited)."""
    ctx.yield_(4)
    seq = viewer.sequence
    report["start_pose_matches"] = bool(np.allclose(viewer.state.pose, seq.poses[0]))
    report["fps"], report["file_fps"] = seq.fps, seq.file_fps
    ctx.set_ref("Pose")
    ctx.item_open("**/Sequence")
    wait_neural(ctx, viewer, report)
    first_version = viewer.neural.version
    ctx.item_click("**/Sequence/Play")
    t0, f0 = time.perf_counter(), seq.frame
    while time.perf_counter() - t0 < 2.5:
        ctx.yield_()
    report["played_frames"], report["played_seconds"] = seq.frame - f0, time.perf_counter() - t0
    report["versions_shown_while_playing"] = len(
        {v for v, _, _, _, _ in viewer.neural.history if v > first_version}
    )
    report["playback_level"] = viewer.neural.playback_level
    ctx.item_click("**/Sequence/Pause")
    ctx.set_ref("Pose")
    ctx.item_click("**/Reset all")
    ctx.yield_(2)
    report["timeline_left_after_reset"] = seq.shown_version != viewer.state.version
    wait_neural(ctx, viewer, report)


def script_open_dialog(ctx, viewer, report: dict) -> None:
    """Sequence > Open...: the native dialog's answer loads the pose file."""
    ctx.yield_(4)
    report["dialog_missing"] = viewer.dialogs.missing()
    ctx.set_ref("Pose")
    ctx.item_open("**/Sequence")
    ctx.item_click("**/Sequence/Open...")
    t0 = time.perf_counter()
    while viewer.sequence is None and time.perf_counter() - t0 < 20:
        ctx.yield_()
    report["sequence_path"] = viewer.sequence_path
    report["sequence_frames"] = None if viewer.sequence is None else len(viewer.sequence.poses)
    report["sequence_error"] = viewer.sequence_error


def script_open_checkpoint(ctx, viewer, report: dict) -> None:
    """File > Open checkpoint...: the dialog's answer is loaded in the background, then the
    window closes to reopen on it (run_viewer's loop; a scripted run stops there)."""
    ctx.yield_(4)
    ctx.set_ref("##MainMenuBar")  # the main viewport's menu bar (hello_imgui)
    ctx.menu_click("File/Open checkpoint...")
    t0 = time.perf_counter()
    while viewer.reopen is None and not viewer.open_error and time.perf_counter() - t0 < 60:
        ctx.yield_()
    ctx.yield_(2)
    report["open_error"] = viewer.open_error
    report["status"] = {"text": viewer.status.text, "error": viewer.status.error}
    report["reopen_source"] = None if viewer.reopen is None else viewer.reopen.source
    report["exit_requested"] = bool(hello_imgui.get_runner_params().app_shall_exit)


def script_reopened(ctx, viewer, report: dict) -> None:
    """The window reopened by File > Open: what it shows."""
    ctx.yield_(4)
    report["source"] = viewer.data.source
    report["sequence_path"] = viewer.sequence_path
    report["sequence_frames"] = None if viewer.sequence is None else len(viewer.sequence.poses)
    report["has_neural"] = viewer.neural is not None


def script_look_stale(ctx, viewer, report: dict) -> None:
    """For a screenshot: a full render, then a new pose; exits while the render is stale."""
    ctx.yield_(4)
    wait_neural(ctx, viewer, report)
    ctx.set_ref("Pose")
    viewer.neural.resolution = 512  # slower levels: the stale image stays a while
    viewer.neural.preview_wait = 0.0  # the pose's frame shows the old image, stale
    viewer.stale_log.clear()
    ctx.item_input_value(*LEFT_ARM_MOVE)
    # the last banner drawn (a loaded machine may finish the new pose's first level while
    # the value is still being typed, so the last frame may be current)
    lines = [line for line in viewer.stale_log if line]
    report["stale_line"] = lines[-1] if lines else viewer.neural_stale_shown


def script_look_views(ctx, viewer, report: dict) -> None:
    """For a screenshot: capture view 1, follow on, the --poses sequence at its last frame
    (joints outside their limits show red), the render finished."""
    ctx.yield_(4)
    ctx.set_ref("3D view")
    ctx.combo_click("##camera/capture view 1")
    ctx.item_click("**/Follow")
    ctx.set_ref("Pose")
    ctx.item_open("**/Sequence")
    ctx.item_input_value("**/Sequence/##frame", len(viewer.sequence.poses) - 1)
    ctx.scroll_to_item("**/left_elbow/##y", imgui.internal.Axis.y)
    wait_neural(ctx, viewer, report)


def script_look_playback(ctx, viewer, report: dict) -> None:
    """For a screenshot: the --poses sequence playing for 4 s."""
    ctx.yield_(4)
    ctx.set_ref("Pose")
    ctx.item_open("**/Sequence")
    ctx.item_click("**/Sequence/Play")
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < 4:
        ctx.yield_()


def script_look_bad_pose(ctx, viewer, report: dict) -> None:
    """For a screenshot: the --poses sequence loaded, then the path
    ``TEXVOCAB_TEST_MISSING_POSES`` names typed in the Sequence field and loaded: the
    error in the status line, the sequence kept."""
    ctx.yield_(4)
    ctx.set_ref("Pose")
    ctx.item_open("**/Sequence")
    ctx.item_input_value("**/Sequence/##path", os.environ["TEXVOCAB_TEST_MISSING_POSES"])
    ctx.item_click("**/Sequence/Load")
    ctx.yield_(4)
    report["status"] = {"text": viewer.status.text, "error": viewer.status.error}
    report["kept"] = None if viewer.sequence is None else len(viewer.sequence.poses)


DAILY_SCRIPTS = {
    "stale": script_stale,
    "camera-view": script_camera_view,
    "playback": script_playback,
    "open-dialog": script_open_dialog,
    "open-checkpoint": script_open_checkpoint,
    "reopened": script_reopened,
    "look-stale": script_look_stale,
    "look-views": script_look_views,
    "look-playback": script_look_playback,
    "look-bad-pose": script_look_bad_pose,
}
