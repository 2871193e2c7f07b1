"""``texvocab view``: the desktop viewer, an imgui-bundle (hello_imgui + GLFW) window with
docked panels over one moderngl context (the window's own; no other GL context is made
in this process): Pose (left), 3D view and Neural render (centre), Vocabulary (right).

``python -m app.window [SOURCE] [--size WxH]`` runs the same window; hidden flags
``--script NAME --report FILE.json [--screenshot FILE.png]`` drive it with the ImGui
Test Engine or a per-frame driver (app/drivers.py) for tests and benchmarks.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from collections import deque

# None of these imports PyOpenGL (imgui_bundle and moderngl do not), so run_viewer can
# still choose its platform first (_choose_gl_platform).
import moderngl
import numpy as np
from imgui_bundle import hello_imgui, imgui, immapp

from app.arguments import NEURAL_NICE, WINDOW_MIN, add_view_arguments, parse_size
from app.camera import OrbitCamera
from app.colors import heat_color
from app.drivers import make_driver
from app.panel_neural import NeuralView, camera_key, draw_neural_panel
from app.panel_pose import PoseSequence, draw_pose_panel, tick_sequence
from app.panel_view import draw_view_panel
from app.panel_vocab import ThumbnailCache, draw_vocab_panel
from app.scene import SceneOptions, SceneRenderer
from app.state import ViewerState, load_viewer_data
from texvocab.errors import TexvocabError
from texvocab.pipeline import march_settings


def _choose_gl_platform() -> None:
    """PyOpenGL (if anything imports it here) must match the window's context: GLX on X11
    (also under Xvfb), EGL on Wayland; an inherited offscreen choice (osmesa) would break."""
    wayland_only = os.environ.get("WAYLAND_DISPLAY") and not os.environ.get("DISPLAY")
    os.environ["PYOPENGL_PLATFORM"] = "egl" if wayland_only else "glx"


def require_display() -> None:
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise TexvocabError("no display ($DISPLAY is not set): use 'texvocab shot' for headless "
                            "images, or run the viewer under xvfb-run")


class Viewer:
    """Everything the panels share: loaded data, the edited pose, the orbit camera, scene
    options, GL resources (made in :meth:`post_init`, inside the window's context) and
    the neural render worker."""

    def __init__(self, data, size: tuple[int, int] = (1280, 800), neural_threads: int = 1,
                 neural_nice: int = NEURAL_NICE):
        self.data, self.size = data, size
        self.state = ViewerState(data)
        self.camera = OrbitCamera()
        self.view_size = (max(size[0] // 3, 16), max(size[1] - 60, 16))
        self.framed = False  # the camera is framed once the 3D view's size is known
        self.reset_camera()
        self.options = SceneOptions()
        self.neural_threads, self.neural_nice = neural_threads, neural_nice
        self.neural_resolution: int | None = None  # long side of the neural render (default 256)
        self.ctx = self.scene = self.thumbs = self.neural = None
        self.preset = ""
        self.sequence = None
        self.sequence_path, self.sequence_error = "", ""
        self.export = None  # the last app.export.Export job
        self.view_rect = (0.0, 0.0, 0.0, 0.0)  # x, y, w, h in window pixels
        self.frame_ms: deque[float] = deque(maxlen=600)  # wall time between frames
        self.frame_cpu_ms: deque[float] = deque(maxlen=600)  # of it, this thread's CPU time
        self.idling_log: deque[tuple[bool, bool]] = deque(maxlen=2000)  # (busy, idling) per frame
        self._last_frame = None
        self._scene_key = None
        self._scene_tex = None
        self.drawn_keys: dict[str, list[tuple[int, int, float]]] = {}

    # -- lifecycle (hello_imgui callbacks) ---------------------------------------------
    def post_init(self) -> None:
        self.ctx = moderngl.create_context()  # attaches to the window's current context
        self.scene = SceneRenderer(self.ctx, self.data)
        self.thumbs = ThumbnailCache(self.ctx, self.data.textures)
        if self.data.model is not None:
            self.neural = NeuralView(self.ctx, self.data.model, march_settings(self.data.settings),
                                     self.neural_threads, self.neural_nice,
                                     settings=self.data.settings)
            if self.neural_resolution:
                self.neural.resolution = int(self.neural_resolution)

    def before_exit(self) -> None:
        if self.neural is not None:
            self.neural.close()
        if self.thumbs is not None:
            self.thumbs.release()
        if self.scene is not None:
            self.scene.release()

    def pre_new_frame(self) -> None:
        now, cpu = time.perf_counter(), time.thread_time()
        if self._last_frame is not None:
            self.frame_ms.append((now - self._last_frame[0]) * 1000)
            self.frame_cpu_ms.append((cpu - self._last_frame[1]) * 1000)
        self._last_frame = (now, cpu)
        tick_sequence(self)
        playing = self.sequence is not None and self.sequence.playing
        busy = self.neural is not None and self.neural.busy
        idling = hello_imgui.get_runner_params().fps_idling
        idling.enable_idling = not (busy or playing)
        self.idling_log.append((busy, bool(idling.enable_idling)))

    # -- helpers for the panels ---------------------------------------------------------
    def reset_camera(self, aspect: float | None = None) -> None:
        """Frame the body of the current pose from the front, in a view of width / height
        ``aspect`` (default: the 3D view's)."""
        aspect = self.view_aspect() if aspect is None else aspect
        verts, _ = self.state.posed()
        lo, hi = verts.min(0), verts.max(0)
        self.camera.target = (lo + hi) / 2.0
        self.camera.yaw, self.camera.pitch = 0.0, 0.0
        half = np.tan(np.radians(self.camera.fov) / 2)
        need = max((hi[1] - lo[1]) / (2 * half), (hi[0] - lo[0]) / (2 * half * aspect))
        self.camera.distance = 1.12 * float(need) + float(hi[2] - lo[2]) / 2

    def render_scene(self, size: tuple[int, int]):
        """The 3D view's texture at ``size``, redrawn only when something changed."""
        if self.scene is None:
            return None
        o = self.options
        key = (self.state.version, camera_key(self.camera), tuple(size), o.textured,
               o.part_colors, o.novelty, o.wireframe, o.skeleton)
        if key != self._scene_key:
            self._scene_tex = self.scene.render(self.state, self.camera, size, o)
            self.ctx.screen.use()
            self._scene_key = key
        return self._scene_tex

    def start_export(self, poses, trans, stem: str, fps: float, view3d: bool = False) -> None:
        """Render ``poses`` (T, 24, 3) from the 3D view's camera at the neural panel's
        resolution in the background (app.export): an MP4, or for one pose neural.png
        (+ view3d.png, the 3D view at the same size, when ``view3d``)."""
        from app.export import Export

        w, h = self.neural.size_for(self.view_aspect())
        camera = self.camera.to_texvocab_camera(w, h)
        image = None
        if view3d:
            self.scene.render(self.state, self.camera, (w, h), self.options)
            image = self.scene.read((w, h))
        march = self.neural.march or march_settings(self.data.settings)
        self.export = Export(self.data.model, march, camera, np.asarray(poses),
                             np.asarray(trans), stem, fps, image)

    def view_aspect(self) -> float:
        w, h = self.view_size
        return w / max(h, 1)

    def view_caption(self) -> str:
        ms = list(self.frame_ms)[-60:]
        fps = f"{1000.0 / np.median(ms):.0f} fps" if ms else ""
        return f"{fps}   left drag: orbit   wheel: zoom   right drag: pan"

    def novelty_colours(self, n: int) -> np.ndarray:
        return heat_color(np.linspace(0.0, 1.0, n))

    def novelty_range(self) -> tuple[float, float]:
        return 0.0, float(self.options.novelty_scale)

    def neural_absent_reason(self) -> str:
        if self.data.capture is None:
            return ("No neural render: no checkpoint loaded (only the body). Start the viewer "
                    "with a trained avatar: texvocab view RUN/checkpoint.pt")
        return (f"No neural render: {self.data.source} is a capture, not a trained avatar. "
                "Train one (texvocab train CAPTURE --out RUN) and open RUN/checkpoint.pt.")


def _cheap_backgrounds(rp, default_style):
    """Panels draw no background of their own; the window is cleared to the same colour.

    Under Mesa llvmpipe every full-window blended layer costs CPU (measured: the viewer's
    frame went from 55 to 35 ms of rasterisation on one core); the docked panels tile the
    window, so their backgrounds were one such layer on top of the clear."""
    def setup() -> None:
        default_style()
        style = imgui.get_style()
        c = style.color_(imgui.Col_.window_bg)
        rp.imgui_window_params.background_color = imgui.ImVec4(c.x, c.y, c.z, 1.0)
        style.set_color_(imgui.Col_.window_bg, imgui.ImVec4(c.x, c.y, c.z, 0.0))
    return setup


def _runner_params(viewer: Viewer, title: str):
    rp = hello_imgui.RunnerParams()
    rp.app_window_params.window_title = title
    rp.app_window_params.window_geometry.size = viewer.size
    rp.app_window_params.restore_previous_geometry = False
    rp.imgui_window_params.default_imgui_window_type = \
        hello_imgui.DefaultImGuiWindowType.provide_full_screen_dock_space
    rp.imgui_window_params.enable_viewports = False
    rp.ini_disable = True
    rp.fps_idling.enable_idling = True
    splits = [
        hello_imgui.DockingSplit("MainDockSpace", "PoseSpace", imgui.Dir.left, 0.22),
        hello_imgui.DockingSplit("MainDockSpace", "VocabSpace", imgui.Dir.right, 0.30),
    ]
    neural_space = "VocabSpace"  # without a model the panel only explains: a tab
    if viewer.data.model is not None:
        splits.append(hello_imgui.DockingSplit("MainDockSpace", "NeuralSpace", imgui.Dir.right,
                                               0.5))
        neural_space = "NeuralSpace"
    rp.docking_params.docking_splits = splits
    windows = []
    for label, space, fn in (("Pose", "PoseSpace", draw_pose_panel),
                             ("3D view", "MainDockSpace", draw_view_panel),
                             ("Neural render", neural_space, draw_neural_panel),
                             ("Vocabulary", "VocabSpace", draw_vocab_panel)):
        win = hello_imgui.DockableWindow(label, space, (lambda f=fn: f(viewer)))
        win.can_be_closed = False
        windows.append(win)
    rp.docking_params.dockable_windows = windows
    rp.callbacks.setup_imgui_style = _cheap_backgrounds(rp, rp.callbacks.setup_imgui_style)
    rp.callbacks.post_init = viewer.post_init
    rp.callbacks.before_exit = viewer.before_exit
    rp.callbacks.pre_new_frame = viewer.pre_new_frame
    return rp


def run_viewer(source: str | None, smpl: str | None = None, size=(1280, 800),
               script: str | None = None, report: str | None = None,
               screenshot: str | None = None, neural_resolution: int | None = None,
               neural_threads: int = 1, poses: str | None = None,
               neural_nice: int = NEURAL_NICE, capture: str | None = None) -> int:
    """Open the viewer window on ``source`` (checkpoint, capture folder or None) and run
    until it is closed. ``poses``: a pose sequence .npz for the timeline (shown at frame
    0). ``script``: a driver from app/drivers.py (tests, benchmarks) writing a JSON
    ``report`` and the last frame to ``screenshot``."""
    require_display()
    _choose_gl_platform()
    data = load_viewer_data(source, smpl, capture)
    viewer = Viewer(data, (int(size[0]), int(size[1])), neural_threads, neural_nice)
    if data.vocab is not None and data.textures is not None:
        print("preparing the vocabulary texture ...", flush=True)
        viewer.state.blended_texture()  # its one-off setup (~2 s) before the window opens
    viewer.neural_resolution = neural_resolution
    if poses:
        viewer.sequence_path = poses
        viewer.sequence = PoseSequence.load(poses)
        viewer.state.set_pose(viewer.sequence.poses[0], viewer.sequence.trans[0])
    rp = _runner_params(viewer, f"texvocab - {data.source}")
    driver = None
    if script is not None:
        driver = make_driver(script, viewer, rp)
    immapp.run(rp)
    if driver is not None:
        shot = hello_imgui.final_app_window_screenshot()
        return driver.finish(report, screenshot, shot)
    return 0


def run_from_args(args: argparse.Namespace) -> int:
    """Run the viewer from :func:`app.arguments.add_view_arguments`' namespace."""
    return run_viewer(args.source, args.smpl, parse_size(args.size, WINDOW_MIN), args.script,
                      args.report, args.screenshot, args.neural_resolution,
                      args.neural_threads, args.poses, args.neural_nice, args.capture)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m app.window", description=__doc__.split("\n")[0])
    add_view_arguments(p)
    args = p.parse_args(argv)
    try:
        return run_from_args(args)
    except TexvocabError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
