"""Scripted runs of the viewer window for what a new user runs into (ImGui Test Engine, as
:mod:`.scripts`): a bad pose path after a good sequence (the error in the status line),
closing the window while a video exports, the layout at a window size and the timeline's
"pose edited since" line in a narrow one."""

from __future__ import annotations

import ctypes
import os
import time
from pathlib import Path

from imgui_bundle import hello_imgui, imgui

from texvocab_viewer.testing.steps import LEFT_ARM_MOVE, wait_neural


def _wait(ctx, done, timeout: float = 30.0) -> None:
    t0 = time.perf_counter()
    while not done() and time.perf_counter() - t0 < timeout:
        ctx.yield_()
    ctx.yield_(2)


def _status(viewer) -> dict:
    s = viewer.status
    return {"text": s.text, "error": s.error, "drawn": s.drawn}


def script_bad_pose(ctx, viewer, report: dict) -> None:
    """With the --poses sequence loaded: File > Open pose file... answered with a bad file,
    the status line hovered; then a path typed in the Sequence field that does not exist;
    its "x" clicked; then the path of a good file. The typed paths come from
    the environment (``TEXVOCAB_TEST_MISSING_POSES``, ``TEXVOCAB_TEST_GOOD_POSES``)."""
    ctx.yield_(4)
    seq = viewer.sequence
    report["start"] = None if seq is None else {"path": seq.path, "frames": len(seq.poses)}
    ctx.set_ref("Pose")
    report["open_at_start"] = bool(ctx.item_exists("**/Sequence/Play"))  # the header opened
    ctx.set_ref("##MainMenuBar")
    ctx.menu_click("File/Open pose file...")
    _wait(ctx, lambda: bool(viewer.sequence_error))
    report["after_dialog"] = _status(viewer)
    report["kept_after_dialog"] = viewer.sequence is seq
    ctx.set_ref("StatusBar")
    ctx.mouse_move("##status")
    ctx.yield_(3)
    report["tooltip"] = viewer.status.tooltip
    ctx.item_click("x")  # the error's close button
    ctx.yield_(2)
    report["after_close"] = _status(viewer)
    ctx.set_ref("Pose")
    report["timeline_shown"] = bool(ctx.item_exists("**/Sequence/##frame"))
    missing = os.environ["TEXVOCAB_TEST_MISSING_POSES"]
    ctx.item_input_value("**/Sequence/##path", missing)
    ctx.item_click("**/Sequence/Load")
    ctx.yield_(3)
    report["after_typo"] = _status(viewer)
    report["kept_after_typo"] = viewer.sequence is seq
    report["play_shown"] = bool(ctx.item_exists("**/Sequence/Play"))
    report["timeline_shown_after"] = bool(ctx.item_exists("**/Sequence/##frame"))
    ctx.item_input_value("**/Sequence/##path", os.environ["TEXVOCAB_TEST_GOOD_POSES"])
    ctx.item_click("**/Sequence/Load")
    ctx.yield_(3)
    report["after_good"] = _status(viewer)
    report["frames_after_good"] = None if viewer.sequence is None else len(viewer.sequence.poses)


def script_close_exporting(ctx, viewer, report: dict) -> None:
    """Export video of the --poses sequence, then close the window (GLFW's close request)
    once a frame or two are written, the export still running."""
    ctx.yield_(4)
    ctx.set_ref("Pose")
    ctx.item_open("**/Sequence")
    ctx.item_click("**/Sequence/Export video")
    t0 = time.perf_counter()
    job = viewer.export
    while (job is None or job.done < 2) and time.perf_counter() - t0 < 60:
        ctx.yield_()
        job = viewer.export
    report["frames_before_close"] = None if job is None else job.done
    report["total"] = None if job is None else job.total
    report["running_at_close"] = bool(job is not None and job.running)
    report["closed_at"] = time.time()
    close_window()  # as the window's close button does
    rp = hello_imgui.get_runner_params()
    t0 = time.perf_counter()
    while not rp.app_shall_exit and time.perf_counter() - t0 < 10:
        ctx.yield_()
    report["closed_by_window"] = bool(rp.app_shall_exit)


def script_close_playing(ctx, viewer, report: dict) -> None:
    """Play the --poses sequence with the neural render at 256 px (busy every frame), then
    close the window (GLFW's close request)."""
    ctx.yield_(4)
    viewer.neural.resolution = 256
    ctx.set_ref("Pose")
    ctx.item_click("**/Sequence/Play")
    seq = viewer.sequence
    _wait(ctx, lambda: seq.frame >= 5 and viewer.neural.busy, timeout=30)
    report["playing_at_close"] = bool(seq.playing)
    report["rendering_at_close"] = bool(viewer.neural.busy)
    report["closed_at"] = time.time()
    close_window()
    rp = hello_imgui.get_runner_params()
    t0 = time.perf_counter()
    while not rp.app_shall_exit and time.perf_counter() - t0 < 10:
        ctx.yield_()
    report["closed_by_window"] = bool(rp.app_shall_exit)


def script_edited_narrow(ctx, viewer, report: dict) -> None:
    """The --poses sequence at frame 0, then a slider moved (the pose leaves the
    sequence): the timeline's "pose edited since" line and the Pose panel's width."""
    ctx.yield_(4)
    ctx.window_focus("Pose")
    ctx.set_ref("Pose")
    ctx.item_open("**/Sequence")
    ctx.yield_(2)
    report["note_before"] = viewer.drawn_timeline_note
    ctx.item_input_value(*LEFT_ARM_MOVE)
    ctx.scroll_to_item("**/Sequence/##frame", imgui.internal.Axis.y)
    ctx.yield_(4)
    note = viewer.drawn_timeline_note
    report["note"] = note
    report["note_width"] = float(imgui.calc_text_size(note).x)
    report["pose_width"] = float(viewer.panel_sizes.get("Pose", (0.0, 0.0, -1))[0])


def _glfw():
    import imgui_bundle

    return ctypes.CDLL(str(Path(imgui_bundle.__file__).parent / "libglfw.so.3"))


def resize_window(width: int, height: int) -> None:
    """glfwSetWindowSize on the window, as a user's drag of its border ends."""
    lib = _glfw()
    lib.glfwSetWindowSize.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_int]
    lib.glfwSetWindowSize(hello_imgui.get_glfw_window_address(), width, height)


def close_window() -> None:
    """Ask GLFW to close the window (glfwSetWindowShouldClose, what the window manager's
    close button sets), through the GLFW library imgui-bundle ships."""
    lib = _glfw()
    lib.glfwSetWindowShouldClose.argtypes = [ctypes.c_void_p, ctypes.c_int]
    lib.glfwSetWindowShouldClose(hello_imgui.get_glfw_window_address(), 1)


def _panel_sizes(ctx, viewer) -> dict:
    """Each panel's size when it is drawn (a panel in a tab brought to the front first)."""
    sizes = {}
    for name in ("Pose", "3D view", "Neural render", "Vocabulary"):
        frame = imgui.get_frame_count()
        if viewer.panel_sizes.get(name, (0, 0, -1))[2] < frame - 1:  # behind another tab
            ctx.window_focus(name)
            ctx.yield_(3)
        w, h, drawn = viewer.panel_sizes.get(name, (0.0, 0.0, -1))
        sizes[name] = {"w": w, "h": h, "drawn": drawn >= frame - 1}
    ctx.window_focus("3D view")
    return sizes


def script_layout(ctx, viewer, report: dict) -> None:
    """The layout this window size got: each panel's size, and the Pose panel scrolled to
    its last slider."""
    ctx.yield_(6)
    frame = imgui.get_frame_count()
    report["drawn_at_start"] = sorted(n for n, (_, _, f) in viewer.panel_sizes.items() if f >= frame - 1)
    report["layout"] = viewer.layout.kind
    report["spaces"] = dict(viewer.layout.spaces)
    report["sizes"] = _panel_sizes(ctx, viewer)
    report["view_size"] = list(viewer.view_size)
    report["relayouts"] = viewer.relayouts
    ctx.window_focus("Pose")
    ctx.set_ref("Pose")
    ctx.scroll_to_item("**/right_hand/##z", imgui.internal.Axis.y)
    report["last_slider_reached"] = bool(ctx.item_exists("**/right_hand/##z"))
    ctx.yield_(3)
    wait_neural(ctx, viewer, report)


def script_resize(ctx, viewer, report: dict) -> None:
    """The window resized to 640x400, then to 1600x1000 (GLFW, as a user's drag of its
    border): the layout each size got and the panels' sizes."""
    ctx.yield_(6)
    report["start"] = viewer.layout.kind
    steps = []
    for w, h in ((640, 400), (1600, 1000)):
        before = viewer.relayouts
        resize_window(w, h)
        _wait(ctx, lambda b=before: viewer.relayouts > b, timeout=15)
        ctx.yield_(6)
        io = imgui.get_io()
        size = [int(io.display_size.x), int(io.display_size.y)]
        steps.append({"size": size, "layout": viewer.layout.kind, "sizes": _panel_sizes(ctx, viewer)})
    report["steps"] = steps


WINDOW_SCRIPTS = {
    "layout": script_layout,
    "resize": script_resize,
    "bad-pose": script_bad_pose,
    "close-exporting": script_close_exporting,
    "close-playing": script_close_playing,
    "edited-narrow": script_edited_narrow,
}
