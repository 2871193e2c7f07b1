"""The per-frame driver of bench/viewer_ui.py (``python -m texvocab_viewer CKPT --script
bench:SECONDS:RES``). No ImGui Test Engine, so nothing but the viewer draws.

Phases, in order:

- ``idle``: nothing changes, the viewer idles as it does for a user (from
  ``time_active_after_last_event`` + 0.5 s, 3.5 s, after the start-up render's last
  level: a margin that keeps any full-speed tail out of the phase). Measured: the CPU
  the process spends outside the neural render (UI, GL under llvmpipe, GLFW) per second
  of wall time, i.e. the share of one core the idle UI takes.
- ``render``: the pose is set to a preset (walk, squat, alternating; ``RENDERS`` in all
  unless the script says how many)
  with the camera of ``texvocab shot --camera 0,0,3.2``, and the progressive render runs
  to full resolution. Measured per render: when each level reached the screen after the
  pose change (after the buffer swap of the first frame that drew it), how long the
  frame that changed the pose took, and the UI's CPU share meanwhile.
- ``after``: 1.5 s after the last render: how many frames the window drew (a delivered
  level wakes it for one frame, app/neural/wake.py).
- ``dragging``: the left shoulder moves every frame as under a dragged slider, with the
  window at full speed (input keeps it awake): UI frame times and CPU per frame, the
  neural images shown meanwhile, and per frame the age of the pose the neural panel
  shows, in UI frames (0: the pose this frame set, 1: the previous frame's, ...; a pose
  from before the drag counts as older than its first frame).
- ``settle``: the drag has stopped (the pose no longer changes); measured: seconds from
  the swap of the last dragged frame to the swap of the first frame that shows the full
  level of its pose (``after_drag_full_s``, one per drag; None if it did not come within
  ``SETTLE_MAX`` seconds). ``DRAGS`` drags and settles alternate, the dragging time
  split evenly between them, so the settle is timed more than once.
"""

from __future__ import annotations

import os
import time

import numpy as np
from imgui_bundle import hello_imgui

from texvocab.pipeline import blas_threads
from texvocab_viewer.gl.camera import DEFAULT_TARGET, OrbitCamera
from texvocab_viewer.testing.driver import Driver

RENDER_POSES = ("walk", "squat")
RENDERS = 12  # default; alternating RENDER_POSES (bench:SECONDS:RES:RENDERS)
AFTER = 1.5  # seconds watched after the last render ("after" phase)
SHOT_CAMERA = (0.0, 0.0, 3.2)  # yaw, pitch, distance: texvocab shot's default --camera
SETTLE_MAX = 10.0  # seconds the "settle" phase waits for the full level
DRAGS = 5  # drags, each followed by a settle; the dragging seconds are split between them


class BenchDriver(Driver):
    """See the module docstring; writes the measurements into the report."""

    def __init__(
        self,
        viewer,
        rp,
        seconds: float = 8.0,
        resolution: int = 256,
        renders: int = RENDERS,
        rest_levels: tuple[int, ...] | None = None,
    ):
        super().__init__("bench", viewer)
        self.seconds, self.resolution, self.render_count = seconds, resolution, renders
        self.rest_levels = rest_levels  # NeuralView.rest_levels (None: the viewer's)
        self.phase, self.t0, self.count = "warmup", time.perf_counter(), 0
        self.drag_ms: list[float] = []
        self.drag_cpu_ms: list[float] = []
        self.drag_process_ms: list[float] = []  # the window process: UI thread + GL threads
        self.drag_panels: list[dict] = []  # UI-thread CPU ms per panel, per dragging frame
        self.drag_levels: list[int] = []  # the level of each new image shown while dragging
        self.drag_level_ms: list[float] = []  # and ms from its job's start to its delivery
        self._drag_shown = None
        #: per dragging frame, the age in UI frames of the pose the neural panel shows
        self.drag_age: list[int] = []
        self._pose_frame: dict[int, int] = {}  # pose version -> the dragging frame that set it
        self._last_drag_swap = None  # when the last dragged frame was swapped
        self._drag_seconds = 0.0  # how long the drags lasted, in all
        self.after_drag: list[float | None] = []  # per drag: its stop to the full level, s
        self.after_drag_render: list[float] = []  # of that, the full render job's own
        self.renders: list[dict] = []
        self._mark = None  # (wall, process CPU, worker CPU) at a phase's start
        self._last = None
        self._last_process = None
        self._nudge = 0
        self._render = None
        self._delivered, self._last_delivery = 0, self.t0  # levels seen in warm-up, when
        previous = rp.callbacks.pre_new_frame
        rp.callbacks.pre_new_frame = lambda: (previous(), self._tick())
        swapped = rp.callbacks.after_swap or (lambda: None)
        rp.callbacks.after_swap = lambda: (swapped(), self._swapped())

    # -- measurement helpers ---------------------------------------------------------------
    def _clock(self) -> tuple[float, float, float]:
        """(wall, this process's CPU outside the render thread, the render's CPU)."""
        nv = self.viewer.neural
        render = 0.0 if nv is None else nv.worker.cpu_seconds()
        inside = nv is not None and nv.worker.in_process
        return (time.perf_counter(), time.process_time() - (render if inside else 0.0), render)

    def _ui_share(self, mark) -> dict:
        """CPU outside the render (thread or process) per wall second since ``mark``
        (cores)."""
        now = self._clock()
        wall = now[0] - mark[0]
        ui = now[1] - mark[1]
        return {
            "seconds": wall,
            "ui_cpu_share": ui / max(wall, 1e-9),
            "render_cpu_share": (now[2] - mark[2]) / max(wall, 1e-9),
        }

    # -- the phases -------------------------------------------------------------------------
    def _tick(self) -> None:
        v = self.viewer
        rp = hello_imgui.get_runner_params()
        now = time.perf_counter()
        self.count += 1
        if self.phase == "done":  # the app exits after this frame
            return
        if self.phase == "warmup":
            rp.fps_idling.enable_idling = False
            delivered = 0 if v.neural is None else len(v.neural.worker.delivered)
            if v.neural is not None and v.neural.history and "startup_s" not in self.report:
                self.report["startup_s"] = now - self.t0  # the window's first level shown
            if delivered != self._delivered:
                self._delivered, self._last_delivery = delivered, now
            # idle starts well after the last delivered level woke the UI
            settled = now - self._last_delivery > rp.fps_idling.time_active_after_last_event + 0.5
            if self.count > 30 and (v.neural is None or not v.neural.busy) and settled:
                self.phase, self._mark = "idle", self._clock()
                self._frames_at_mark = self.count
            return
        if self.phase == "idle":
            if now - self._mark[0] >= self.seconds:
                self.report["idle"] = self._ui_share(self._mark)
                self.report["idle"]["frames"] = self.count - self._frames_at_mark
                if v.neural is None:
                    self._done(rp, "no neural render: the source is not a checkpoint")
                    return
                v.neural.resolution = self.resolution
                v.neural.rest_levels = self.rest_levels
                self.phase = "render"
            return
        if self.phase == "render":
            self._render_tick(now)
            return
        if self.phase == "after":
            self._after_tick(now)
            return
        if self.phase == "settle":  # the window idles as the viewer lets it (a level wakes it)
            if now - self.t0 > SETTLE_MAX:
                self.after_drag.append(None)
                self._done(rp)
            return
        rp.fps_idling.enable_idling = False  # "dragging": input keeps the window awake
        if not self._nudge:  # the drag starts in this frame
            self.t0 = now
        if now - self.t0 > self.seconds / DRAGS:  # the drag stops: the pose set last frame stays
            self.phase, self._drag_seconds = "settle", self._drag_seconds + now - self.t0
            self.t0 = now
            return
        shown = v.neural.frame
        if shown is not None and shown is not self._drag_shown:
            self._drag_shown = shown
            self.drag_levels.append(int(shown.level))
            self.drag_level_ms.append(shown.elapsed * 1000)
        dt, self._last = (None if self._last is None else (now - self._last) * 1000), now
        process = self._clock()[1]  # the window process's CPU outside a render thread
        dp, self._last_process = (
            (None if self._last_process is None else (process - self._last_process) * 1000),
            process,
        )
        if dt is not None and v.frame_cpu_ms:
            self.drag_ms.append(dt)
            self.drag_cpu_ms.append(v.frame_cpu_ms[-1])
            self.drag_process_ms.append(dp)
            self.drag_panels.append(dict(v.panel_cpu_ms))
        self._nudge += 1
        z = -60.0 + 50.0 * abs((self._nudge % 60) / 30.0 - 1.0)  # sweep -60..-10 deg
        v.state.set_joint(16, (0.0, 0.0, z))

    def _start_render(self, now: float) -> None:
        v = self.viewer
        pose = RENDER_POSES[len(self.renders) % len(RENDER_POSES)]
        v.state.reset_all()
        v.state.apply_preset(pose)
        yaw, pitch, dist = SHOT_CAMERA
        v.camera = OrbitCamera(
            target=np.asarray(DEFAULT_TARGET) + v.state.trans, yaw=yaw, pitch=pitch, distance=dist
        )
        self._render = {
            "pose": pose,
            "start": now,
            "levels": [],
            "seen": len(v.neural.history),
            "first_frame": self.count,
        }
        self._mark = self._clock()

    def _swapped(self) -> None:
        """After a frame is on screen: the levels it showed for the first time (uploaded in
        this frame, before or while the panels drew) are on screen now."""
        nv, r = self.viewer.neural, self._render
        now = time.perf_counter()
        if self.phase in ("dragging", "settle"):
            self._drag_swapped(now)
            return
        if self.phase != "render" or r is None:
            return
        r.setdefault("pose_frame_s", now - r["start"])  # the frame that changed the pose
        history = list(nv.history)
        for version, level, ms, elapsed, shape in history[r["seen"] :]:
            if version == nv.version:
                r["levels"].append(
                    {
                        "level": level,
                        "on_screen_s": now - r["start"],
                        "worker_elapsed_s": elapsed,
                        "level_ms": ms,
                        "size": [int(x) for x in shape],
                    }
                )
        r["seen"] = len(history)

    def _drag_swapped(self, now: float) -> None:
        """After a dragging frame's swap: the age of the pose the neural panel shows; in
        the settle phase, whether the last pose's full level is on screen."""
        nv, pose = self.viewer.neural, self.viewer.state.version
        shown = nv.on_screen
        key = None if shown is None else nv.keys.get(shown.version)
        if self.phase == "settle":
            if shown is not None and shown.level == 1 and key is not None and key[0] == pose:
                self.after_drag.append(now - self._last_drag_swap)
                self.after_drag_render.append(shown.elapsed)  # of that, the job's own
                if len(self.after_drag) < DRAGS:  # the next drag starts with the next frame
                    self.phase, self.t0, self._nudge = "dragging", now, 0
                    self._last = self._last_process = None
                    self._drag_shown = nv.frame  # the settle's full level is not a drag's
                else:
                    self._done(hello_imgui.get_runner_params())
            return
        if not self._nudge:  # the pose has not moved yet
            return
        i = len(self.drag_age)
        self._pose_frame.setdefault(pose, i)
        born = None if key is None else self._pose_frame.get(key[0])
        self.drag_age.append(i - born if born is not None else i + 1)
        self._last_drag_swap = now

    def _render_tick(self, now: float) -> None:
        nv = self.viewer.neural
        r = self._render
        if r is None:
            if not nv.busy:  # the resolution's render (first render) is not timed
                self._start_render(now)
            return
        done = r["levels"] and r["levels"][-1]["level"] == 1 and not nv.busy
        if done or now - r["start"] > 600:
            r.update(self._ui_share(self._mark))
            # the pose frame's wait for the preview (NeuralView.wait_preview): ms, whether it came
            r["preview_wait"] = next(
                ([round(s * 1000, 2), came] for v, s, came in nv.waits if v == nv.version), None
            )
            r["frames"] = self.count - r.pop("first_frame")
            r.pop("seen")
            r.pop("start")
            self.renders.append(r)
            self._render = None
            if len(self.renders) >= self.render_count:
                self.phase, self.t0, self._frames_at_mark = "after", now, self.count

    def _after_tick(self, now: float) -> None:
        """Frames drawn in the AFTER seconds after the last render finished: a level's wake
        draws one frame, it does not keep the window at full speed."""
        if now - self.t0 >= AFTER:
            self.report["after_render"] = {
                "seconds": now - self.t0,
                "frames": self.count - self._frames_at_mark,
            }
            self.phase, self.t0 = "dragging", now
            self._drag_shown = self.viewer.neural.frame
            hello_imgui.get_runner_params().fps_idling.enable_idling = False  # the next frame at once

    def _done(self, rp, error: str | None = None) -> None:
        v = self.viewer
        self.phase = "done"
        self.report["ok"] = error is None
        if error:
            self.report["error"] = error
        self.report["renders"] = self.renders
        self.report["dragging"] = {
            "frame_ms": self.drag_ms,
            "cpu_ms": self.drag_cpu_ms,
            "process_cpu_ms": self.drag_process_ms,
            "levels_shown": self.drag_levels,
            "preview_age_frames": self.drag_age,
            "level_ms": self.drag_level_ms,
            "panel_cpu_ms": self.drag_panels,
            "seconds": self._drag_seconds or time.perf_counter() - self.t0,
        }
        self.report["after_drag_full_s"] = self.after_drag
        self.report["after_drag_render_s"] = self.after_drag_render
        self.report["window"] = list(v.size)
        if v.neural is not None:
            self.report["resolution"] = self.resolution
            self.report["neural_threads"] = v.neural_threads
            self.report["neural_processes"] = v.neural_processes if v.neural.worker.in_process is False else 0
            self.report["neural_worker"] = v.neural_worker
            self.report["window_pid"] = os.getpid()
            self.report["blas_threads"] = blas_threads()
            self.report["render_pid"] = getattr(v.neural.worker, "pid", os.getpid())
            self.report["errors"] = list(v.neural.worker.errors)
        rp.app_shall_exit = True


def drag_stats(report: dict) -> dict:
    """The dragging measurement's summary: p95 of the shown pose's age in UI frames, how
    many dragging frames showed a pose at most one frame old, p95 of the frame times (ms),
    and seconds from a drag's stop to the full level on screen: the median over the drags
    (None: one did not come) and the list of them (``after_drag_full_all_s``)."""
    age = np.asarray(report["dragging"].get("preview_age_frames", []))
    ms = np.asarray(report["dragging"]["frame_ms"])
    settles = report.get("after_drag_full_s") or []
    if not isinstance(settles, list):  # a report from before several drags
        settles = [settles]
    return {
        "drag_preview_age_frames_p95": float(np.percentile(age, 95)) if len(age) else float("nan"),
        "drag_frames_within_1": (int((age <= 1).sum()), len(age)),
        "drag_frame_ms_p95": float(np.percentile(ms, 95)) if len(ms) else float("nan"),
        "after_drag_full_s": None if not settles or None in settles else float(np.median(settles)),
        "after_drag_full_all_s": settles,
    }
