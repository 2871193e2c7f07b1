"""Scripted runs of the viewer window for tests, screenshots and benchmarks (``python -m
app.window SOURCE --script NAME --report R.json [--screenshot S.png]``).

Scripts that act like a user run inside the ImGui Test Engine (they move sliders and
click widgets by their IDs, as a person would with the mouse); the benchmark uses a
per-frame driver instead so the engine adds nothing to the frame times. Every script
writes a JSON report and exits the app; the last frame goes to ``--screenshot``.
"""
from __future__ import annotations

import json
import time
import traceback
from pathlib import Path

import numpy as np
from imgui_bundle import hello_imgui, imgui

from texvocab.errors import TexvocabError
from texvocab.pipeline import atomic_write_bytes, save_png

LEFT_ARM_MOVE = ("**/left_shoulder/##z", -70.0)  # lower the left arm from the T-pose


def snapshot(viewer) -> dict:
    """What the vocabulary panel last drew, per part: [(key id, frame, weight)], and the
    parts' nearest-key distances."""
    return {"keys": {p: [list(k) for k in v] for p, v in viewer.drawn_keys.items()},
            "novelty": {q.part: float(q.novelty) for q in viewer.state.query()}}


def wait_neural(ctx, viewer, report: dict, timeout: float = 60.0) -> None:
    """Yield frames until the neural render reached full resolution (or ``timeout``)."""
    if viewer.neural is None:
        return
    t0 = time.perf_counter()
    ctx.yield_(2)
    while (viewer.neural.busy or viewer.neural.frame is None) and \
            time.perf_counter() - t0 < timeout:
        ctx.yield_()
    ctx.yield_(2)
    log = list(viewer.idling_log)  # (worker busy, playing, idling enabled) per frame so far
    report["idling_while_busy"] = sorted({idle for busy, play, idle in log if busy and not play})
    report["idling_while_playing"] = sorted({idle for _, play, idle in log if play})
    report["idling_when_done"] = bool(hello_imgui.get_runner_params().fps_idling.enable_idling)
    f = viewer.neural.frame
    report["neural"] = None if f is None else {
        "level": f.level, "ms": f.seconds * 1000, "size": list(f.image.shape[:2]),
        "corner": [float(c) for c in f.image[0, 0]],
        "delivered": [list(d) for d in viewer.neural.worker.delivered],
        "errors": list(viewer.neural.worker.errors),
        "traceback": viewer.neural.worker.last_traceback}


def script_slider(ctx, viewer, report: dict) -> None:
    """Move a left-arm slider; record the vocabulary panel before and after."""
    ctx.yield_(6)
    report["before"] = snapshot(viewer)
    report["version_before"] = viewer.state.version
    ctx.set_ref("Pose")
    ctx.item_input_value(*LEFT_ARM_MOVE)
    ctx.yield_(4)
    report["after"] = snapshot(viewer)
    report["version_after"] = viewer.state.version
    report["left_shoulder_deg"] = viewer.state.joint_deg(16).tolist()
    shown = {}
    ctx.set_ref("Vocabulary")
    for key_id, _, _ in viewer.drawn_keys.get("left_arm", []):
        shown[str(key_id)] = bool(ctx.item_exists(f"left_arm/keys/key{key_id}"))
    report["left_arm_buttons_found"] = shown
    far_key = report["after"]["keys"]["left_arm"][-1][0]  # the farthest selected key
    ctx.item_click(f"left_arm/keys/key{far_key}")
    ctx.yield_(3)
    report["clicked_key"] = far_key
    report["after_click"] = snapshot(viewer)
    _camera_steps(ctx, viewer, report)
    if viewer.sequence_path:
        _sequence_steps(ctx, viewer, report)
    wait_neural(ctx, viewer, report)


def _camera(viewer) -> dict:
    c = viewer.camera
    return {"yaw": c.yaw, "pitch": c.pitch, "distance": c.distance, "target": c.target.tolist()}


def _camera_steps(ctx, viewer, report: dict) -> None:
    """Orbit (left drag), zoom (wheel) and pan (right drag) in the 3D view."""
    ctx.set_ref("3D view")
    report["camera_start"] = _camera(viewer)
    ctx.mouse_move("**/##viewport")
    ctx.mouse_drag_with_delta(imgui.ImVec2(60, 0))
    report["camera_orbited"] = _camera(viewer)
    ctx.mouse_move("**/##viewport")
    ctx.mouse_wheel_y(2)
    ctx.yield_(2)
    report["camera_zoomed"] = _camera(viewer)
    ctx.mouse_move("**/##viewport")
    ctx.mouse_drag_with_delta(imgui.ImVec2(0, 40), imgui.MouseButton_.right)
    report["camera_panned"] = _camera(viewer)
    ctx.item_click("**/Reset camera")
    ctx.yield_(2)
    report["camera_reset"] = _camera(viewer)


def _sequence_steps(ctx, viewer, report: dict) -> None:
    """Load the pose file given by --poses and scrub its timeline to frame 2."""
    ctx.set_ref("Pose")
    ctx.item_open("**/Sequence")
    ctx.item_click("**/Sequence/Load")
    ctx.yield_(2)
    report["sequence_error"] = viewer.sequence_error
    if viewer.sequence is None:
        return
    report["sequence_frames"] = len(viewer.sequence.poses)
    ctx.item_input_value("**/Sequence/##frame", 2)
    ctx.yield_(2)
    report["sequence_frame"] = viewer.sequence.frame
    report["pose_at_frame"] = viewer.state.pose.tolist()
    report["trans_at_frame"] = viewer.state.trans.tolist()
    ctx.item_click("**/Sequence/Play")
    seq = viewer.sequence
    t0 = time.perf_counter()
    while seq.frame == 2 and time.perf_counter() - t0 < 10:
        ctx.yield_()
    report["played_to"] = seq.frame
    report["played_pose_matches"] = bool(np.allclose(viewer.state.pose, seq.poses[seq.frame]))
    ctx.item_click("**/Sequence/Pause")
    paused_at = seq.frame
    ctx.yield_(5)
    report["paused"] = not seq.playing and seq.frame == paused_at


def script_shot_default(ctx, viewer, report: dict) -> None:
    ctx.yield_(6)
    wait_neural(ctx, viewer, report)


def script_shot_left_arm(ctx, viewer, report: dict) -> None:
    ctx.yield_(4)
    ctx.set_ref("Pose")
    ctx.item_input_value(*LEFT_ARM_MOVE)
    ctx.item_input_value("**/left_elbow/##y", -60.0)
    ctx.yield_(4)
    report["after"] = snapshot(viewer)
    wait_neural(ctx, viewer, report)


def script_shot_novelty(ctx, viewer, report: dict) -> None:
    ctx.yield_(4)
    ctx.set_ref("Pose")
    ctx.item_input_value("**/left_shoulder/##z", 60.0)  # raise the left arm
    ctx.item_input_value("**/right_hip/##x", -90.0)
    ctx.set_ref("3D view")
    ctx.item_click("**/Novelty")
    ctx.item_click("**/Skeleton")
    ctx.item_click("**/Reset camera")  # frame the new pose
    ctx.yield_(4)
    report["novelty_on"] = bool(viewer.options.novelty)
    report["skeleton_on"] = bool(viewer.options.skeleton)
    report["after"] = snapshot(viewer)
    wait_neural(ctx, viewer, report)


def wait_export(ctx, viewer, timeout: float = 120.0) -> dict:
    t0 = time.perf_counter()
    ctx.yield_(2)
    while viewer.export is not None and viewer.export.running and \
            time.perf_counter() - t0 < timeout:
        ctx.yield_()
    ctx.yield_(2)
    job = viewer.export
    return {"path": None if job is None or job.path is None else str(job.path.resolve()),
            "error": None if job is None else job.error,
            "frames": None if job is None else job.done}


def script_export(ctx, viewer, report: dict) -> None:
    """Load the --poses sequence, turn Follow on, click "Export video", then "Screenshot";
    wait for each."""
    ctx.yield_(4)
    ctx.set_ref("Pose")
    ctx.item_open("**/Sequence")
    ctx.item_click("**/Sequence/Load")
    ctx.yield_(2)
    report["sequence_frames"] = None if viewer.sequence is None else len(viewer.sequence.poses)
    report["fps"] = None if viewer.sequence is None else viewer.sequence.fps
    ctx.set_ref("3D view")
    ctx.item_click("**/Follow")  # the video's cameras then move with the root
    report["follow"] = viewer.follow
    ctx.set_ref("Pose")
    ctx.item_click("**/Sequence/Export video")
    report["video"] = wait_export(ctx, viewer)
    ctx.set_ref("3D view")
    ctx.item_click("**/Screenshot")
    report["screenshot"] = wait_export(ctx, viewer)


ENGINE_SCRIPTS = {"slider": script_slider, "shot-default": script_shot_default,
                  "export": script_export, "shot-left-arm": script_shot_left_arm,
                  "shot-novelty": script_shot_novelty}


def engine_scripts() -> dict:
    """Every ImGui Test Engine script by name (these and app/drivers_daily.py's)."""
    from app.drivers_daily import DAILY_SCRIPTS

    return {**ENGINE_SCRIPTS, **DAILY_SCRIPTS}


#: a scripted run whose window reopens (File > Open) goes on with this script, whose
#: report replaces the first one
AFTER_REOPEN = {"open-checkpoint": "reopened"}


class Driver:
    """Common end of a scripted run: the report and the final frame."""

    def __init__(self, name: str, viewer):
        self.name, self.viewer = name, viewer
        self.report: dict = {"script": name, "ok": False}

    def finish(self, report_path: str | None, screenshot_path: str | None, shot) -> int:
        v = self.viewer
        self.report["view_rect"] = list(v.view_rect)
        self.report["window"] = list(v.size)
        self.report["window_sample_buffers"] = v.window_sample_buffers
        self.report["view_blits"] = v.view_blits
        self.report["preview_blits"] = v.preview_blits
        if v.neural is not None:
            self.report["worker_stopped"] = not v.neural.worker.alive
        if screenshot_path and shot is not None and shot.size:
            self.report["screenshot"] = str(save_png(Path(screenshot_path), shot[..., :3]))
            self.report["screenshot_shape"] = list(shot.shape)
        if report_path:
            blob = json.dumps(self.report, indent=1)
            atomic_write_bytes(Path(report_path), lambda t: Path(t).write_text(blob))
        return 0 if self.report.get("ok") else 1


class EngineDriver(Driver):
    """Runs one script as an ImGui Test Engine test, then exits the app."""

    def __init__(self, name: str, viewer, rp):
        super().__init__(name, viewer)
        self.script = engine_scripts()[name]
        rp.use_imgui_test_engine = True
        rp.callbacks.register_tests = self._register

    def _register(self) -> None:
        engine = hello_imgui.get_imgui_test_engine()
        io = imgui.test_engine.get_io(engine)
        io.config_run_speed = imgui.test_engine.TestRunSpeed.fast
        io.config_log_to_tty = True
        self.test = imgui.test_engine.register_test(engine, "texvocab", self.name)
        self.test.test_func = self._run
        imgui.test_engine.queue_test(engine, self.test)

    def _run(self, ctx) -> None:
        try:
            self.script(ctx, self.viewer, self.report)
            self.report["ok"] = not ctx.is_error()
        except BaseException:  # noqa: BLE001 - reported, then the app exits
            self.report["error"] = traceback.format_exc()
        finally:
            self.report["engine_log"] = self.test.output.log.get_text()[-4000:]
            hello_imgui.get_runner_params().app_shall_exit = True


def make_driver(name: str, viewer, rp) -> Driver:
    """The driver for ``--script NAME``: an engine script or
    ``bench[:SECONDS[:RES[:RENDERS]]]``."""
    if name.startswith("bench"):
        from app.bench_driver import RENDERS, BenchDriver

        parts = name.split(":")
        seconds = float(parts[1]) if len(parts) > 1 else 8.0
        res = int(parts[2]) if len(parts) > 2 else 256
        renders = int(parts[3]) if len(parts) > 3 else RENDERS
        return BenchDriver(viewer, rp, seconds, res, renders)
    if name not in engine_scripts():
        raise TexvocabError(f"--script {name!r}: expected one of {sorted(engine_scripts())} or "
                            "bench[:SECONDS[:RESOLUTION[:RENDERS]]]")
    return EngineDriver(name, viewer, rp)
