"""The viewer's shared state, one object the panels draw from: the loaded data, the
edited pose (:class:`texvocab_viewer.state.ViewerState`), the camera (orbit, or a capture camera as a
preset; optionally following the root), scene options, GL resources, the neural render
worker, screenshots and exports, and the File menu's dialogs. The window around it is
:mod:`texvocab_viewer.window`."""

from __future__ import annotations

import time
from collections import deque

import moderngl
import numpy as np
from imgui_bundle import hello_imgui, imgui

from texvocab.pipeline import march_settings
from texvocab_viewer.arguments import DRAG_FRAME_MS, NEURAL_NICE
from texvocab_viewer.controls.camera import CameraControls
from texvocab_viewer.controls.exports import ExportControls, follow_cameras
from texvocab_viewer.controls.files import FileControls
from texvocab_viewer.dialogs import FileDialogs
from texvocab_viewer.gl.colors import heat_color
from texvocab_viewer.gl.scene import SceneOptions, SceneRenderer
from texvocab_viewer.gl.view_blit import (
    ViewBlit,
    blit_image,
    blit_view,
    gl_flush,
    image_rects,
    warm_image_blit,
    window_framebuffer,
)
from texvocab_viewer.layout import dock_splits, layout_for, needs_relayout
from texvocab_viewer.neural.view import NeuralView, camera_key, start_worker
from texvocab_viewer.neural.wake import ui_waker
from texvocab_viewer.panels.neural import late_draw
from texvocab_viewer.panels.pose import tick_sequence
from texvocab_viewer.panels.vocab import ThumbnailCache
from texvocab_viewer.state import ViewerState
from texvocab_viewer.status import StatusLine

__all__ = ["SUBMIT_AFTER", "Viewer", "follow_cameras"]

#: panels whose widgets change the pose: the neural job is submitted as soon as they are
#: drawn, not when the Neural render panel draws after the 3D view (8 ms later, or more)
SUBMIT_AFTER = ("Pose",)


class Viewer(CameraControls, FileControls, ExportControls):
    """Everything the panels share: loaded data, the edited pose, the orbit camera, scene
    options, GL resources (made in :meth:`post_init`, inside the window's context), the
    neural render worker and the status line. The camera, the File menu and the exports
    are in :mod:`texvocab_viewer.controls`."""

    def __init__(
        self,
        data,
        size: tuple[int, int] = (1280, 800),
        neural_threads: int = 1,
        neural_nice: int = NEURAL_NICE,
        neural_worker: str = "process",
    ):
        self.data, self.size = data, size
        self.state = ViewerState(data)
        self.camera = self.new_orbit()
        self.follow = False  # the camera moves with the body's root
        self._follow_ref = np.zeros(3)
        self.view_size = (max(size[0] // 3, 16), max(size[1] - 60, 16))
        self.framed = False  # the camera is framed once the 3D view's size is known
        self.reset_camera()
        self.options = SceneOptions()
        self.neural_threads, self.neural_nice = neural_threads, neural_nice
        self.neural_worker = neural_worker  # "process" or "thread" (texvocab_viewer.arguments)
        self.neural_processes = 1  # render processes splitting a view (run_viewer sets it)
        self.neural_preview_wait: float | None = None  # seconds (None: the panel's default)
        self._worker = None  # started by start_neural_worker, handed to the panel
        self.neural_resolution: int | None = None  # long side of the neural render (default 256)
        self.ctx = self.scene = self.thumbs = self.neural = None
        self.window_sample_buffers: int | None = None  # read from GL in post_init
        self.preset = ""
        self.sequence = None
        self.sequence_path, self.sequence_error = "", ""
        self.sequence_root = "floor"  # where a pose file stands in the capture's world (ROOTS)
        #: calls a scripted run asks the window's thread to make (GL is current only there),
        #: made after the frame's panels (before_imgui_render)
        self.window_thread_calls: deque = deque()
        self.export = None  # the last texvocab_viewer.export.job.Export job
        self.view_rect = (0.0, 0.0, 0.0, 0.0)  # x, y, w, h in window pixels
        self.view_blit: ViewBlit | None = None  # where the 3D view's image goes this frame
        self.view_blits = 0  # frames whose 3D view was copied into the window
        self.preview_blits = 0  # frames whose awaited preview was drawn just before the swap
        self._warmed = False  # the preview blit's code compiled (warm_image_blit)
        self.frame_ms: deque[float] = deque(maxlen=600)  # wall time between frames
        self.frame_cpu_ms: deque[float] = deque(maxlen=600)  # of it, this thread's CPU time
        self.panel_cpu_ms: dict[str, float] = {}  # per panel: UI-thread CPU of its last draw
        self.idling_log: deque[tuple] = deque(maxlen=2000)  # (busy, playing, idling) per frame
        self._last_frame = None
        self._waited_at = None  # when this frame's wait for a preview ended
        self.wait_tails: deque[float] = deque(maxlen=32)  # seconds from a wait's end to the next frame
        self._scene_key = None
        self._scene_tex = None
        self.drawn_keys: dict[str, list[tuple[int, int, float]]] = {}
        self.drawn_moved: list[str] = []  # the parts the vocabulary panel highlighted
        self.drawn_distances: dict[str, list[tuple[int, float]]] = {}  # per part: key, bar
        self.neural_stale_shown = ""  # the stale line (NeuralView.stale_line) last drawn
        self.stale_log: deque[str] = deque(maxlen=2000)  # that line, per frame drawn
        self.neural_banner_drawn = ""  # the banner over the stale image, cut to its width
        self.neural_tooltip = ""  # the banner's whole text, when the image was hovered
        self.dialogs = FileDialogs()
        self.reopen = None  # ViewerData chosen in File > Open: the window restarts on it
        self.open_error = ""
        self.smpl: str | None = None
        self.layout = None  # where the panels dock (texvocab_viewer.layout.Layout; the window sets it)
        self.panel_sizes: dict[str, tuple[float, float, int]] = {}  # per panel: w, h, frame drawn
        self.drawn_timeline_note = ""  # the Pose panel's "pose edited since" line, last drawn
        self._laid_out_for: tuple[int, int] | None = None  # window size of the last layout
        self._laid_out_at = 0  # its frame
        self.relayouts = 0  # layouts since the window opened (a resize that called for one)
        self.status = StatusLine()  # the last error or success, at the window's bottom
        self.open_sequence = False  # the Pose panel opens its Sequence header once
        self._export_seen = None  # the export job whose outcome the status line has shown

    # -- lifecycle (hello_imgui callbacks) ---------------------------------------------
    def post_init(self) -> None:
        self.ctx = moderngl.create_context()  # attaches to the window's current context
        # 0 unless the window's own framebuffer is multisampled (texvocab_viewer.window.WINDOW_MSAA_SAMPLES)
        self.window_sample_buffers = int(self.ctx.info["GL_SAMPLE_BUFFERS"])
        self.scene = SceneRenderer(self.ctx, self.data)
        self.thumbs = ThumbnailCache(self.ctx, self.data.textures)
        if self.data.model is not None:
            self.start_neural_worker()
            self.neural = NeuralView(
                self.ctx,
                self.data.model,
                march_settings(self.data.settings),
                self.neural_threads,
                self.neural_nice,
                settings=self.data.settings,
                worker=self._worker,
            )
            if self.neural_resolution:
                self.neural.resolution = int(self.neural_resolution)
            if self.neural_preview_wait is not None:
                self.neural.preview_wait = self.neural_preview_wait

    def start_neural_worker(self) -> None:
        """Start the neural render's worker (once; nothing without a model). The window
        calls this before it opens, so a render process starts up (torch, the model)
        while the window does."""
        if self._worker is None and self.data.model is not None:
            self._worker = start_worker(
                self.neural_worker,
                self.data.model,
                march_settings(self.data.settings),
                self.neural_threads,
                self.neural_nice,
                ui_waker(),
                self.neural_processes,
            )

    def before_exit(self) -> None:
        if self.export is not None and self.export.running:
            self.export.cancel()  # its partial files removed
        if self.neural is not None:
            self.neural.close()
        if self.thumbs is not None:
            self.thumbs.release()
        if self.scene is not None:
            self.scene.release()

    def follow_window_size(self) -> None:
        """Dock the panels anew when the window was resized to a size that calls for
        another layout, or that left a panel under its floor (texvocab_viewer.layout)."""
        if self.layout is None:
            return
        io = imgui.get_io()
        size = (int(io.display_size.x), int(io.display_size.y))
        if min(size) <= 0:
            return
        resized = size != self._laid_out_for
        if self._laid_out_for is None:
            self._laid_out_for = size
            return
        wanted = layout_for(*size, self.data.model is not None)
        frame = imgui.get_frame_count()
        # panels drawn in the last frame; a fresh layout gets a few frames to settle
        widths = {n: w for n, (w, _, f) in self.panel_sizes.items() if f >= frame - 1}
        if frame - self._laid_out_at < 3 or not needs_relayout(self.layout, wanted, resized, widths):
            return
        rp = hello_imgui.get_runner_params()
        rp.docking_params.docking_splits = dock_splits(wanted)
        windows = rp.docking_params.dockable_windows
        for win in windows:
            win.dock_space_name = wanted.spaces[win.label]
            win.focus_window_at_next_frame = wanted.kind == "tabs" and win.label == "3D view"
        rp.docking_params.dockable_windows = windows
        rp.docking_params.layout_reset = True
        self.layout, self._laid_out_for, self._laid_out_at = wanted, size, frame
        self.relayouts += 1

    def draw_panel(self, name: str, draw) -> None:
        """Draw one docked panel (``draw(viewer)``), timing its UI-thread CPU."""
        cpu = time.thread_time()
        if imgui.get_current_context() is not None:  # (tests call panels without a window)
            size = imgui.get_window_size()
            self.panel_sizes[name] = (size.x, size.y, imgui.get_frame_count())
        draw(self)
        if name in SUBMIT_AFTER:  # its sliders change the pose: the render starts now
            self.submit_neural(poll=False)
        self.panel_cpu_ms[name] = (time.thread_time() - cpu) * 1000

    def pre_new_frame(self) -> None:
        now, cpu = time.perf_counter(), time.thread_time()
        if self._last_frame is not None:
            self.frame_ms.append((now - self._last_frame[0]) * 1000)
            self.frame_cpu_ms.append((cpu - self._last_frame[1]) * 1000)
        self._last_frame = (now, cpu)
        if self._waited_at is not None:  # the last frame waited for a preview: its tail
            self.wait_tails.append(now - self._waited_at)
            self._waited_at = None
        self.view_blit = None  # the 3D view panel sets it if it draws this frame
        self.poll_dialogs()
        self.follow_window_size()
        self.show_export_outcome()
        tick_sequence(self)
        self.follow_root()
        self.submit_neural()
        playing = self.sequence is not None and self.sequence.playing
        busy = self.neural is not None and self.neural.busy
        idling = hello_imgui.get_runner_params().fps_idling
        idling.enable_idling = not playing  # a render in progress wakes the UI per level
        self.idling_log.append((busy, playing, bool(idling.enable_idling)))
        self.panel_cpu_ms["before the panels"] = (time.thread_time() - cpu) * 1000

    def before_imgui_render(self) -> None:
        """After the panels, before ImGui draws: the neural render's last poll and its
        image, then the 3D view's image into the window."""
        if self.neural is not None:
            self.neural.late_poll()
            late_draw(self)
        if self.view_blit is not None:
            self.view_blits += blit_view(self.view_blit, *window_framebuffer())
            self.ctx.screen.use()  # moderngl's idea of the bound framebuffer, again
        if self.window_thread_calls:
            while self.window_thread_calls:
                self.window_thread_calls.popleft()()
            self.ctx.screen.use()

    def before_swap(self) -> None:
        """After ImGui drew the frame, before the swap: when this frame changed the pose
        (after a pause, or under a dragged slider), llvmpipe rasterises the frame while the
        UI waits for the pose's preview (NeuralView.wait_preview; while dragging, at most
        until DRAG_FRAME_MS after the frame began), which is then drawn over the panel's
        image, so the 3D view and the preview reach the screen together. Not with a popup
        open (it could lie over the image)."""
        nv = self.neural
        if nv is not None and not self._warmed:
            colour = hello_imgui.get_runner_params().imgui_window_params.background_color
            warm_image_blit(self.ctx, (colour.x, colour.y, colour.z))
            self._warmed = True
        if nv is None or not nv.awaiting:
            return
        rect = nv.image_rect
        if rect is None or imgui.is_popup_open("", imgui.PopupFlags_.any_popup_id):
            nv.cancel_wait()
            return
        gl_flush()  # the frame so far rasterises while the render process finishes
        waited = nv.wait_preview(self.drag_until())
        self._waited_at = time.perf_counter()
        if not waited:
            return
        rects = image_rects(rect, nv.texture.size, *window_framebuffer())
        if rects is not None:
            fbo = self.ctx.framebuffer(color_attachments=[nv.texture])
            blit_image(fbo.glo, rects)
            fbo.release()
            self.preview_blits += 1
            nv.on_screen = nv.frame
        self.ctx.screen.use()

    def drag_until(self) -> float:
        """When a dragged frame's wait for its preview must end (perf_counter):
        DRAG_FRAME_MS after the frame began, less the time recent frames took after their
        wait (the swap, input; the 90th percentile of the last 32, 4 ms before any)."""
        if self._last_frame is None:
            return -np.inf
        tail = float(np.percentile(self.wait_tails, 90)) if self.wait_tails else 0.004
        return self._last_frame[0] + DRAG_FRAME_MS / 1000 - tail

    def submit_neural(self, force: bool = False, poll: bool = True) -> None:
        """Hand a changed pose or camera to the neural render worker (and, with ``poll``,
        show a finished level). Called before the panels draw and again after the Pose
        panel, so the render starts before this frame's UI work (the vocabulary texture,
        the 3D view) rather than after it."""
        if self.neural is None:
            return
        playing = self.sequence is not None and self.sequence.playing
        self.neural.update(
            self.state,
            self.camera,
            self.neural_aspect(),
            force,
            self.pose_label(),
            playing,
            self.options.background,
            poll,
        )

    def pose_label(self) -> str:
        """What the current pose is, for the render's stale label: a sequence frame, or
        the last edit (ViewerState.change)."""
        seq = self.sequence
        if seq is not None and seq.shown_version == self.state.version:
            return f"frame {seq.frame}"
        return self.state.change

    # -- helpers for the panels ---------------------------------------------------------
    def render_scene(self, size: tuple[int, int]):
        """The 3D view's texture at ``size``, redrawn only when something changed."""
        if self.scene is None:
            return None
        o = self.options
        key = (
            self.state.version,
            camera_key(self.camera),
            tuple(size),
            o.textured,
            o.part_colors,
            o.novelty,
            o.wireframe,
            o.skeleton,
        )
        if key != self._scene_key:
            self._scene_tex = self.scene.render(self.state, self.camera, size, o)
            self.ctx.screen.use()
            self._scene_key = key
        return self._scene_tex

    def view_caption(self) -> str:
        """The 3D view's one line: a screenshot in progress, or the mouse's controls
        (outcomes and errors go to the status line)."""
        job = self.export
        if job is not None and job.total == 1 and job.running:
            return "screenshot: rendering ..."
        return "left drag: orbit   wheel: zoom   right drag: pan   F12: screenshot"

    def show_export_outcome(self) -> None:
        """Once an export has finished: what it wrote, or why it failed, in the status line."""
        job = self.export
        if job is None or job.running or job is self._export_seen:
            return
        self._export_seen = job
        what = "screenshot" if job.total == 1 else "video"
        if job.error:
            self.status.fail(f"{what} not written: {job.error}")
        elif job.path is not None:
            self.status.done(f"{what}: wrote {job.path}")

    def novelty_colours(self, n: int) -> np.ndarray:
        return heat_color(np.linspace(0.0, 1.0, n))

    def novelty_range(self) -> tuple[float, float]:
        return 0.0, float(self.options.novelty_scale)

    def neural_absent_reason(self) -> str:
        if self.data.capture is None:
            return (
                "No neural render: no checkpoint loaded (only the body). Start the viewer "
                "with a trained avatar: texvocab view RUN/checkpoint.pt"
            )
        return (
            f"No neural render: {self.data.source} is a capture, not a trained avatar. "
            "Train one (texvocab train CAPTURE --out RUN) and open RUN/checkpoint.pt."
        )
