"""``texvocab view``: the desktop viewer, an imgui-bundle (hello_imgui + GLFW) window with
docked panels over one moderngl context (the window's own; no other GL context is made
in this process): Pose (left), 3D view and Neural render (centre), Vocabulary (right).

``python -m texvocab_viewer [SOURCE] [--size WxH]`` runs the same window
(:mod:`texvocab_viewer.launch`). A test or benchmark drives it with a :data:`Script`
(:mod:`texvocab_viewer.testing`), which the window knows only by this interface.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Protocol

# None of these imports PyOpenGL (imgui_bundle and moderngl do not), so run_viewer can
# still choose its platform first (_choose_gl_platform).
import numpy as np
from imgui_bundle import hello_imgui, imgui, immapp

from texvocab.errors import TexvocabError
from texvocab.pipeline import budget_blas_threads
from texvocab_viewer.arguments import NEURAL_NICE, NEURAL_PREVIEW_WAIT_MS, NEURAL_PROCESSES
from texvocab_viewer.layout import dock_splits, layout_for
from texvocab_viewer.panels.pose import check_pose_file, load_sequence
from texvocab_viewer.panels.registry import PANELS
from texvocab_viewer.state import load_viewer_data
from texvocab_viewer.status import draw_status
from texvocab_viewer.viewer import Viewer

#: frames per second while nothing changes (no input, no new render level, no playback):
#: each frame of this window costs tens of ms of CPU under llvmpipe, which the neural
#: render thread needs. A finished render level wakes the window at once
#: (hello_imgui.request_refresh from the worker), input does as always.
IDLE_FPS = 1.0

#: MSAA samples of the window's own framebuffer. hello_imgui asks for 8 (GL's maximum: 4
#: under llvmpipe), which ImGui does not need (it antialiases its shapes and text itself;
#: the 3D view draws into its own framebuffer): under llvmpipe the multisampled buffer and
#: its resolve at every swap cost an empty 1280x800 window 15.5 ms a frame and 28 ms of
#: CPU, against 5.2 and 7.7 ms without.
WINDOW_MSAA_SAMPLES = 0


class ScriptedRun(Protocol):
    """A test's or benchmark's run of one window, set up by a :data:`Script`."""

    def finish(self, shot: np.ndarray | None, reopens: bool) -> tuple[int, Script | None]:
        """After the window closed, with its last frame ``shot`` (H, W, 4) uint8: the exit
        code, and the script of the window that reopens (``reopens``: File > Open chose a
        source), or None to stop there."""
        ...


#: ``script(viewer, runner_params)``, called before each window opens, sets up its run
#: (hooks into the runner parameters' callbacks, or the ImGui Test Engine)
Script = Callable[[Viewer, hello_imgui.RunnerParams], ScriptedRun]


def _choose_gl_platform() -> None:
    """PyOpenGL (if anything imports it here) must match the window's context: GLX on X11
    (also under Xvfb), EGL on Wayland; an inherited offscreen choice (osmesa) would break."""
    wayland_only = os.environ.get("WAYLAND_DISPLAY") and not os.environ.get("DISPLAY")
    os.environ["PYOPENGL_PLATFORM"] = "egl" if wayland_only else "glx"


def require_display() -> None:
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise TexvocabError(
            "no display ($DISPLAY is not set): use 'texvocab shot' for headless "
            "images, or run the viewer under xvfb-run"
        )


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
    rp.imgui_window_params.menu_app_title = "texvocab"  # the menu bar's first menu: short, File fits
    rp.app_window_params.window_geometry.size = viewer.size
    rp.app_window_params.restore_previous_geometry = False
    rp.imgui_window_params.default_imgui_window_type = (
        hello_imgui.DefaultImGuiWindowType.provide_full_screen_dock_space
    )
    rp.imgui_window_params.enable_viewports = False
    rp.renderer_backend_options.open_gl_options.anti_aliasing_samples = WINDOW_MSAA_SAMPLES
    rp.ini_disable = True
    rp.fps_idling.enable_idling = True
    rp.fps_idling.fps_idle = IDLE_FPS
    rp.imgui_window_params.show_menu_bar = True
    rp.imgui_window_params.show_menu_view = False
    rp.callbacks.show_menus = viewer.show_menus
    rp.imgui_window_params.show_status_bar = True  # the last error or outcome (app/status.py)
    rp.imgui_window_params.show_status_fps = False
    rp.imgui_window_params.remember_status_bar_settings = False
    rp.callbacks.show_status = lambda: draw_status(viewer.status)
    viewer.layout = layout_for(*viewer.size, viewer.data.model is not None)
    rp.docking_params.docking_splits = dock_splits(viewer.layout)
    windows = []
    for panel in PANELS:
        win = hello_imgui.DockableWindow(
            panel.title,
            viewer.layout.spaces[panel.title],
            (lambda f=panel.draw, name=panel.title: viewer.draw_panel(name, f)),
        )
        win.can_be_closed = False
        # one column of tabs: the 3D view in front
        win.focus_window_at_next_frame = viewer.layout.kind == "tabs" and panel.title == "3D view"
        windows.append(win)
    rp.docking_params.dockable_windows = windows
    rp.callbacks.setup_imgui_style = _cheap_backgrounds(rp, rp.callbacks.setup_imgui_style)
    rp.callbacks.post_init = viewer.post_init
    rp.callbacks.before_exit = viewer.before_exit
    rp.callbacks.pre_new_frame = viewer.pre_new_frame
    rp.callbacks.before_imgui_render = viewer.before_imgui_render
    rp.callbacks.before_swap = viewer.before_swap
    return rp


def run_viewer(
    source: str | None,
    smpl: str | None = None,
    size=(1280, 800),
    script: Script | None = None,
    neural_resolution: int | None = None,
    neural_threads: int = 1,
    poses: str | None = None,
    neural_nice: int = NEURAL_NICE,
    capture: str | None = None,
    neural_worker: str = "process",
    neural_processes: int = NEURAL_PROCESSES,
    neural_preview_wait_ms: float = NEURAL_PREVIEW_WAIT_MS,
    other_capture: bool = False,
) -> int:
    """Open the viewer window on ``source`` (checkpoint, capture folder or None) and run
    until it is closed. ``poses``: a pose sequence .npz for the timeline (shown at frame
    0). ``script``: a scripted run of the window (tests, benchmarks; its exit code is
    returned). ``neural_worker``: "process" or "thread"
    (texvocab_viewer.arguments.NEURAL_WORKERS); ``neural_processes``: how many render
    processes split each view; ``other_capture``: accept a ``capture`` the checkpoint
    was not trained on (one warning line); ``neural_preview_wait_ms``:
    texvocab_viewer.neural.view.NeuralView.preview_wait."""
    if poses:
        check_pose_file(poses)  # a bad file is refused before the avatar loads
    require_display()
    _choose_gl_platform()
    budget_blas_threads(1)  # the frame's numpy products: no spinning OpenBLAS thread
    data = load_viewer_data(source, smpl, capture, other_capture)
    while True:
        viewer = Viewer(data, (int(size[0]), int(size[1])), neural_threads, neural_nice, neural_worker)
        viewer.smpl = smpl
        viewer.neural_processes = int(neural_processes)
        viewer.neural_preview_wait = float(neural_preview_wait_ms) / 1000
        viewer.start_neural_worker()  # a render process starts up meanwhile
        if data.vocab is not None and data.textures is not None:
            print("preparing the vocabulary texture ...", flush=True)
            viewer.state.blended_texture()  # its one-off setup (~2 s) before the window opens
        viewer.neural_resolution = neural_resolution
        if poses:
            load_sequence(viewer, poses)
            if viewer.sequence_error:
                raise TexvocabError(viewer.sequence_error)
        rp = _runner_params(viewer, f"texvocab - {data.source}")
        run = None if script is None else script(viewer, rp)
        immapp.run(rp)
        if run is not None:
            rc, script = run.finish(hello_imgui.final_app_window_screenshot(), viewer.reopen is not None)
            if script is None:
                return rc
        elif viewer.reopen is None:
            return 0
        data, poses = viewer.reopen, viewer.sequence_path or None  # File > Open
        print(f"opening {data.source}", flush=True)
