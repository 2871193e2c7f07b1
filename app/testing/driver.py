"""The common end of a scripted run of the viewer window (its JSON report and its last
frame) and the driver that runs one ImGui Test Engine script in the window."""

from __future__ import annotations

import json
import traceback
from collections.abc import Callable
from pathlib import Path

from imgui_bundle import hello_imgui, imgui

from texvocab.pipeline import atomic_write_bytes, save_png


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


#: an ImGui Test Engine script: ``script(ctx, viewer, report)`` acts on the window through
#: the engine's context and writes what it saw into the report
EngineScript = Callable[[object, object, dict], None]


class EngineDriver(Driver):
    """Runs ``script`` as an ImGui Test Engine test named ``name``, then exits the app."""

    def __init__(self, name: str, script: EngineScript, viewer, rp):
        super().__init__(name, viewer)
        self.script = script
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
