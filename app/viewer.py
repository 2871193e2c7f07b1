"""The viewer's shared state, one object the panels draw from: the loaded data, the
edited pose (:class:`texvocab_viewer.state.ViewerState`), the camera (orbit, or a capture camera as a
preset; optionally following the root), scene options, GL resources, the neural render
worker, screenshots and exports, and the File menu's dialogs. The window around it is
:mod:`texvocab_viewer.window`."""

from __future__ import annotations

import threading
import time
from collections import deque

import moderngl
import numpy as np
from imgui_bundle import hello_imgui, imgui

from texvocab.errors import TexvocabError
from texvocab.pipeline import follow_camera, march_settings
from texvocab_viewer.arguments import NEURAL_NICE
from texvocab_viewer.dialogs import POSE_FILTERS, SOURCE_FILTERS, FileDialogs
from texvocab_viewer.export.job import Export
from texvocab_viewer.gl.camera import CaptureViewCamera, OrbitCamera, orbit_for
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
from texvocab_viewer.neural.wake import ui_waker
from texvocab_viewer.panels.neural import NeuralView, camera_key, late_draw, start_worker
from texvocab_viewer.panels.pose import load_sequence, tick_sequence
from texvocab_viewer.panels.vocab import ThumbnailCache
from texvocab_viewer.state import ViewerState, load_viewer_data

#: panels whose widgets change the pose: the neural job is submitted as soon as they are
#: drawn, not when the Neural render panel draws after the 3D view (8 ms later, or more)
SUBMIT_AFTER = ("Pose",)


class Viewer:
    """Everything the panels share: loaded data, the edited pose, the orbit camera, scene
    options, GL resources (made in :meth:`post_init`, inside the window's context) and
    the neural render worker."""

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
        self._scene_key = None
        self._scene_tex = None
        self.drawn_keys: dict[str, list[tuple[int, int, float]]] = {}
        self.neural_stale_shown = ""  # the stale banner the neural panel last drew
        self.stale_log: deque[str] = deque(maxlen=2000)  # that banner, per frame drawn
        self.dialogs = FileDialogs()
        self.reopen = None  # ViewerData chosen in File > Open: the window restarts on it
        self.open_error = ""
        self.smpl: str | None = None

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
        if self.neural is not None:
            self.neural.close()
        if self.thumbs is not None:
            self.thumbs.release()
        if self.scene is not None:
            self.scene.release()

    def draw_panel(self, name: str, draw) -> None:
        """Draw one docked panel (``draw(viewer)``), timing its UI-thread CPU."""
        cpu = time.thread_time()
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
        self.view_blit = None  # the 3D view panel sets it if it draws this frame
        self.poll_dialogs()
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

    def before_swap(self) -> None:
        """After ImGui drew the frame, before the swap: when this frame changed the pose
        after a pause, llvmpipe rasterises the frame while the UI waits for the pose's
        preview (NeuralView.wait_preview), which is then drawn over the panel's image, so
        the 3D view and the preview reach the screen together. Not with a popup open (it
        could lie over the image)."""
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
        if not nv.wait_preview():
            return
        rects = image_rects(rect, nv.texture.size, *window_framebuffer())
        if rects is not None:
            fbo = self.ctx.framebuffer(color_attachments=[nv.texture])
            blit_image(fbo.glo, rects)
            fbo.release()
            self.preview_blits += 1
        self.ctx.screen.use()

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

    # -- cameras ------------------------------------------------------------------------
    def root_position(self) -> np.ndarray:
        """(3,) world position of the root joint (pelvis) in the current pose."""
        return self.state.posed()[1][0].astype(np.float64)

    def set_follow(self, on: bool) -> None:
        """Follow mode: the camera moves with the root. Turning it on centres the root
        horizontally in an orbit view (its height offset is kept); a capture view keeps
        its framing and moves along."""
        self.follow = bool(on)
        root = self.root_position()
        if isinstance(self.camera, CaptureViewCamera):
            self._follow_ref = root - self.camera.shift
        else:
            self._follow_ref = np.array([0.0, self.camera.target[1] - root[1], 0.0])
        self.follow_root()

    def follow_root(self) -> None:
        if not self.follow:
            return
        root = self.root_position()
        if isinstance(self.camera, CaptureViewCamera):
            self.camera.shift = root - self._follow_ref
        else:
            self.camera.target = root + self._follow_ref

    def set_capture_view(self, index: int | None) -> None:
        """Look through capture camera ``index`` (as ``texvocab shot --camera N``), or with
        None go back to the orbit camera (from the capture camera's place)."""
        cap = self.data.capture
        if index is None:
            if isinstance(self.camera, CaptureViewCamera):
                self.camera = self.camera.to_orbit(self.body_centre())
        else:
            if cap is None or not 0 <= index < cap.num_views:
                raise TexvocabError(f"camera {index}: no such capture view")
            self.camera = CaptureViewCamera(cap.cameras[index], index)
        if self.follow:
            self.set_follow(True)

    def orbit_camera(self) -> OrbitCamera:
        """The orbit camera, leaving a capture view for the nearest orbit (a drag in the
        3D view does this)."""
        if isinstance(self.camera, CaptureViewCamera):
            self.set_capture_view(None)
        return self.camera

    def body_centre(self) -> np.ndarray:
        verts, _ = self.state.posed()
        return (verts.min(0) + verts.max(0)).astype(np.float64) / 2.0

    def neural_aspect(self) -> float:
        """Width / height of the neural render: the capture camera's, or the 3D view's."""
        if isinstance(self.camera, CaptureViewCamera):
            return self.camera.aspect
        return self.view_aspect()

    def pose_label(self) -> str:
        """What the current pose is, for the render's stale label: a sequence frame, or
        the last edit (ViewerState.change)."""
        seq = self.sequence
        if seq is not None and seq.shown_version == self.state.version:
            return f"frame {seq.frame}"
        return self.state.change

    # -- helpers for the panels ---------------------------------------------------------
    def new_orbit(self) -> OrbitCamera:
        """An orbit camera about the world's up axis (:func:`orbit_for`)."""
        return orbit_for(self.data.capture)

    def reset_camera(self, aspect: float | None = None) -> None:
        """Frame the body of the current pose from the front, in a view of width / height
        ``aspect`` (default: the 3D view's)."""
        if isinstance(self.camera, CaptureViewCamera):
            self.camera = self.new_orbit()
        aspect = self.view_aspect() if aspect is None else aspect
        verts, _ = self.state.posed()
        local = verts @ self.camera.basis.T  # right, up, front (x, y, z when +y is up)
        lo, hi = local.min(0), local.max(0)
        self.camera.target = ((lo + hi) / 2.0) @ self.camera.basis
        self.camera.yaw, self.camera.pitch = 0.0, 0.0
        half = np.tan(np.radians(self.camera.fov) / 2)
        need = max((hi[1] - lo[1]) / (2 * half), (hi[0] - lo[0]) / (2 * half * aspect))
        self.camera.distance = 1.12 * float(need) + float(hi[2] - lo[2]) / 2
        if self.follow:
            self.set_follow(True)

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

    def shot_size(self) -> tuple[int, int]:
        """Size of a screenshot: a capture camera's own image size (what ``texvocab shot
        --camera N`` writes), else the neural render's full level (the 3D view's size
        without a model)."""
        if isinstance(self.camera, CaptureViewCamera):
            return self.camera.camera.width, self.camera.camera.height
        if self.neural is not None:
            return self.neural.size_for(self.view_aspect())
        return self.view_size

    def start_export(self, poses, trans, stem: str, fps: float, view3d: bool = False) -> None:
        """Render ``poses`` (T, 24, 3) from the 3D view's camera at :meth:`shot_size` in
        the background (texvocab_viewer.export.job): an MP4, or for one pose neural.png (+ view3d.png, the
        3D view at the same size, when ``view3d``; only that without a model)."""
        w, h = self.shot_size()
        camera = self.camera.to_texvocab_camera(w, h)
        if self.follow and len(poses) > 1:  # the camera moves with the root, as in the view
            camera = follow_cameras(camera, np.asarray(trans), self.state.trans)
        image = None
        if view3d:
            self.scene.render(self.state, self.camera, (w, h), self.options)
            image = self.scene.read((w, h))
            self.ctx.screen.use()
        model, march = None, None
        if self.neural is not None:
            model = self.data.model
            march = self.neural.march or march_settings(self.data.settings)
        self.export = Export(
            model,
            march,
            camera,
            np.asarray(poses),
            np.asarray(trans),
            stem,
            fps,
            image,
            background=self.options.background,
        )

    def screenshot(self) -> None:
        """The Screenshot button and F12: the 3D view and the neural render of the current
        pose, written under exports/shot*/ (never replacing a file)."""
        if self.export is None or not self.export.running:
            self.start_export(self.state.pose[None], self.state.trans[None], "shot", 1.0, view3d=True)

    def view_aspect(self) -> float:
        w, h = self.view_size
        return w / max(h, 1)

    def view_caption(self) -> str:
        if self.open_error:
            return f"could not open {self.open_error}"
        job = self.export
        if job is not None and job.total == 1:
            if job.running:
                return "screenshot: rendering ..."
            if job.error:
                return f"screenshot failed: {job.error}"
            if job.path is not None:
                return f"screenshot: wrote {job.path}"
        return "left drag: orbit   wheel: zoom   right drag: pan   F12: screenshot"

    # -- File menu and its dialogs --------------------------------------------------------
    def show_menus(self) -> None:
        """The File menu: open a checkpoint or capture (the window restarts on it), open a
        pose file, screenshot."""
        missing = self.dialogs.missing()
        if imgui.begin_menu("File"):
            if imgui.menu_item("Open checkpoint...", "", False, not missing)[0]:
                self.dialogs.ask("source", "Open a checkpoint", SOURCE_FILTERS)
            if imgui.menu_item("Open pose file...", "", False, not missing)[0]:
                self.dialogs.ask("poses", "Open a pose file", POSE_FILTERS, self.sequence_path)
            if missing:
                imgui.text_disabled(missing)
            imgui.separator()
            if imgui.menu_item("Screenshot", "F12", False, True)[0]:
                self.screenshot()
            imgui.end_menu()

    def poll_dialogs(self) -> None:
        """Act on a file dialog's answer (once per frame)."""
        if self.reopen is not None:
            hello_imgui.get_runner_params().app_shall_exit = True
        answer = self.dialogs.poll()
        if answer is None:
            return
        purpose, path = answer
        if purpose == "poses":
            load_sequence(self, path)
        elif purpose == "source":
            self.open_source(path)

    def open_source(self, path: str) -> None:
        """Load a checkpoint or capture in the background; when it loaded, the window
        closes and reopens on it (the pose sequence stays); an error stays in the caption."""

        def load() -> None:
            try:
                self.reopen = load_viewer_data(path, self.smpl)
            except Exception as exc:  # noqa: BLE001 - any failure is shown, the window stays
                self.open_error = f"{path}: {exc}"
            hello_imgui.request_refresh()

        self.open_error = ""
        threading.Thread(target=load, name="texvocab-open", daemon=True).start()

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


def follow_cameras(camera, trans: np.ndarray, now: np.ndarray) -> list:
    """One camera per frame of root translations ``trans`` (T, 3): ``camera`` (the view
    at root translation ``now``) moved with the root, as follow mode moves the view (the
    root joint is its rest position plus the translation)."""
    return [follow_camera(camera, t - np.asarray(now, np.float64)) for t in trans]
