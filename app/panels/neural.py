"""Neural render panel: the trained avatar rendered by the CPU ray marcher in a render
process (:mod:`texvocab_viewer.neural.render_process`; or a thread,
:mod:`texvocab_viewer.neural.worker`), from the 3D view's camera, coarse to fine (1/8 .. 1),
with the level shown and how long it took.
Without a checkpoint it says why it is empty.

Widget IDs: window "Neural render", ``**/Live``, ``**/resolution``, ``**/Render now``,
``**/preset``.
"""

from __future__ import annotations

import time
from collections import deque

import numpy as np
from imgui_bundle import imgui

from texvocab.pipeline import RENDER_PRESETS as PRESETS
from texvocab.pipeline import march_settings, render_overrides
from texvocab_viewer.arguments import NEURAL_PREVIEW_WAIT_MS
from texvocab_viewer.neural.render_process import ProcessWorker
from texvocab_viewer.neural.worker import ProgressiveWorker, RenderFrame, RenderJob, model_renderer

#: during playback the render follows the timeline at one level: a finer one when a
#: frame took under half this many seconds, a coarser one when it took more
PLAYBACK_SECONDS = 0.5
STALE_TINT = (0.45, 0.45, 0.45, 1.0)
#: a submission follows a pause when the one before is at least this many seconds older:
#: only then does its frame wait for the preview (NeuralView.preview_wait). Poses that
#: stream in, as under a dragged slider, never hold a frame.
PREVIEW_PAUSE = 0.25


class NeuralView:
    """The neural render's GUI state: the worker, the displayed level's GL texture, and
    the version counter bumped whenever pose, camera or resolution change.

    While a sequence plays, renders are not cancelled by each new frame (none would ever
    finish): the worker renders the newest pose at one level (:attr:`playback_level`),
    and when it is done the then-newest pose follows."""

    def __init__(
        self,
        ctx,
        model,
        march,
        threads: int = 1,
        nice: int = 0,
        settings=None,
        on_frame=None,
        worker="process",
    ):
        self.ctx = ctx
        self.worker = (
            worker
            if not isinstance(worker, str)
            else start_worker(worker, model, march, threads, nice, on_frame)
        )
        self.settings = settings  # the checkpoint's Settings (for the presets)
        self.preset = "checkpoint"  # or a texvocab.pipeline.settings.PRESETS name
        self.march = None  # MarchSettings of the chosen preset (None: the checkpoint's)
        self.image_scale = 1.0
        self.live = True
        self.resolution = 256  # long side of the full-resolution level, pixels
        self.version = 0
        self.playback_level = 8
        self._playback_job = False  # the last submitted job is a playback render
        self._key = None
        self.frame: RenderFrame | None = None
        self.texture = None
        self.labels: dict[int, str] = {}  # version -> what it shows ("frame 12", "edit 40")
        self.keys: dict[int, tuple] = {}  # version -> the view it renders (pose, camera, ...)
        self._current: tuple | None = None  # those of the view now
        self._current_label = ""
        #: (version, level, milliseconds, seconds since the job started, (h, w)) per shown level
        self.history: deque[tuple] = deque(maxlen=200)
        #: seconds from a submission after a pause that its frame waits, after the panels,
        #: for the new pose's first level, so the 3D view and the preview reach the screen
        #: in one frame (``--neural-preview-wait``; 0: never)
        self.preview_wait = NEURAL_PREVIEW_WAIT_MS / 1000
        #: (version, seconds waited, whether the preview came) per waiting frame
        self.waits: deque[tuple[int, float, bool]] = deque(maxlen=200)
        self._submitted_at = -np.inf  # perf_counter of the last submission
        self._await: tuple[int, float] | None = None  # (version, deadline) for late_poll
        self._playing = False
        #: where draw_neural_panel left room for the status line and the image (late_draw)
        self.canvas: dict | None = None
        #: where late_draw put the image this frame: x0, y0, x1, y1 (None: not drawn)
        self.image_rect: tuple[float, float, float, float] | None = None

    @property
    def busy(self) -> bool:
        return self.worker.busy

    @property
    def stale(self) -> bool:
        """True while the shown image belongs to an older pose, camera or size (also with
        Live off, when nothing new is being rendered)."""
        return self.frame is not None and self.keys.get(self.frame.version) != self._current

    def size_for(self, aspect: float) -> tuple[int, int]:
        """(w, h) of the full-resolution level for a view of ``aspect``."""
        return _fit(max(8, round(self.resolution * self.image_scale)), aspect)

    def update(
        self,
        state,
        camera,
        aspect: float,
        force: bool = False,
        label: str = "",
        playing: bool = False,
        background=(0.0, 0.0, 0.0),
        poll: bool = True,
    ) -> None:
        """Submit a job when the pose, camera or size changed (while ``playing``: only
        once the previous one is done); with ``poll``, upload a new level (not while the
        panel's image may already be in this frame's draw list). ``label`` names the
        pose; ``background``: the 3D view's, so both panels (and screenshots) match."""
        w, h = self.size_for(aspect)
        view = (state.version, camera_key(camera), w, h, self.preset, tuple(background))
        key = (*view, playing)
        self._current, self._current_label = view, label or f"edit {state.version}"
        changed = (self.live and key != self._key) or force
        # while playing, a playback render in progress is let finish (a full render from
        # before Play is cancelled at once)
        wait = playing and self.worker.busy and self._playback_job and not force
        if changed and not wait:
            self._key = key
            self._playback_job = playing
            self.version += 1
            self.labels[self.version] = self._current_label
            self.keys[self.version] = view  # pose, camera, size, preset, background
            for old in [v for v in self.labels if v < self.version - 64]:
                del self.labels[old], self.keys[old]
            levels = (self.playback_level,) if playing else None
            now = time.perf_counter()
            paused = now - self._submitted_at >= PREVIEW_PAUSE
            self._await = (
                (self.version, now + self.preview_wait)
                if paused and not playing and self.preview_wait > 0
                else None
            )
            self._submitted_at = now
            # playback renders one level and is never cancelled by the timeline anyway
            self.worker.submit(
                RenderJob(
                    self.version,
                    state.pose.copy(),
                    state.trans.copy(),
                    camera.to_texvocab_camera(w, h),
                    self.march,
                    levels,
                    tuple(background),
                    finish_preview=not playing,
                )
            )
        self._playing = playing
        if poll:
            self._take(self.worker.poll())

    def _take(self, frame: RenderFrame | None) -> None:
        if frame is not None:
            self._upload(frame)
            if self._playing:
                self._adapt_playback_level(frame)

    def late_poll(self) -> None:
        """After the frame's panels, before ImGui draws: take the newest level, so one
        that arrived while the frame was built is in it (:func:`late_draw`). A preview this
        frame was to wait for that came so counts as a wait of 0 s."""
        self._take(self.worker.poll())
        pending = self._await
        if pending is not None and self.frame is not None and self.frame.version >= pending[0]:
            self.waits.append((pending[0], 0.0, True))
            self._await = None

    @property
    def awaiting(self) -> bool:
        """True when this frame submitted a pose after a pause whose preview is not shown
        yet: :meth:`wait_preview` would wait for it."""
        pending = self._await
        return (
            pending is not None
            and pending[0] == self.version
            and (self.frame is None or self.frame.version < pending[0])
        )

    def cancel_wait(self) -> None:
        """This frame does not wait for its preview (it shows a frame later)."""
        self._await = None

    def wait_preview(self) -> bool:
        """After ImGui drew the frame, before the swap: if :attr:`awaiting`, wait for the
        pose's preview until ``preview_wait`` seconds after its submission and take it.
        True when a level of the pose was taken (the caller draws it over the frame)."""
        if not self.awaiting:
            self._await = None
            return False
        pending, self._await = self._await, None
        start = time.perf_counter()
        came = self.worker.wait_for(pending[0], pending[1] - start)
        self.waits.append((pending[0], time.perf_counter() - start, came))
        frame = self.worker.poll()
        self._take(frame)
        return frame is not None and frame.version >= pending[0]

    def _adapt_playback_level(self, frame: RenderFrame) -> None:
        if frame.elapsed < PLAYBACK_SECONDS / 2 and self.playback_level > 1:
            self.playback_level //= 2
        elif frame.elapsed > PLAYBACK_SECONDS and self.playback_level < 8:
            self.playback_level *= 2

    def set_preset(self, name: str) -> None:
        """Render with a speed/accuracy preset's render knobs (bench/tradeoff.py), or with
        the checkpoint's own settings ("checkpoint")."""
        self.preset = name
        if name == "checkpoint" or self.settings is None:
            self.march, self.image_scale = None, 1.0
            return
        s = render_overrides(self.settings, name, [])
        self.march, self.image_scale = march_settings(s), s.render.image_scale

    def stale_line(self) -> str:
        """ "stale: shows frame 12; rendering frame 15" (or "" when the image is current)."""
        if not self.stale:
            return ""
        shown = self.labels.get(self.frame.version, "an older pose")
        if self.keys.get(self.version) != self._current:  # Live is off: nothing on its way
            return f"stale: shows {shown}; Live is off (Render now)"
        return f"stale: shows {shown}; rendering {self.labels.get(self.version, 'the new pose')}"

    def _upload(self, frame: RenderFrame) -> None:
        img = np.ascontiguousarray((np.clip(frame.image, 0, 1) * 255 + 0.5).astype(np.uint8))
        size = (img.shape[1], img.shape[0])
        if self.texture is None or self.texture.size != size:
            if self.texture is not None:
                self.texture.release()
            self.texture = self.ctx.texture(size, 3)
            self.texture.filter = (self.ctx.LINEAR, self.ctx.LINEAR)
        self.texture.write(img.tobytes())
        self.frame = frame
        self.history.append((frame.version, frame.level, frame.seconds * 1000, frame.elapsed, img.shape[:2]))

    def close(self) -> None:
        self.worker.stop()
        if self.texture is not None:
            self.texture.release()
            self.texture = None


def start_worker(kind: str, model, march, threads: int = 1, nice: int = 0, on_frame=None, processes: int = 1):
    """The neural render's worker: "process" (``processes`` processes of their own, which
    split each view: the UI's Python does not slow the render; about 3.5-4 s from start
    to the first level, torch imported and the model unpickled there) or "thread" (in
    the viewer's interpreter)."""
    if kind == "process":
        return ProcessWorker(
            model_renderer, (model, march), threads=threads, nice=nice, on_frame=on_frame, processes=processes
        )
    return ProgressiveWorker(model_renderer(model, march), threads=threads, nice=nice, on_frame=on_frame)


def _fit(long_side: int, aspect: float) -> tuple[int, int]:
    """(w, h) with the long side ``long_side`` and w / h = aspect (both >= 8)."""
    if aspect >= 1:
        return long_side, max(8, round(long_side / aspect))
    return max(8, round(long_side * aspect)), long_side


def camera_key(camera) -> tuple:
    """What identifies the view of an orbit camera or a capture-camera preset."""
    if hasattr(camera, "key"):
        return camera.key()
    return (
        float(camera.yaw),
        float(camera.pitch),
        float(camera.distance),
        float(camera.fov),
        *(float(v) for v in camera.target),
    )


def status_line(
    frame: RenderFrame | None, busy: bool, playback_level: int | None = None, stale: bool = False
) -> str:
    """What the shown image is and how long it took; during playback, the level the render
    follows the timeline at."""
    if frame is None:
        return "rendering..." if busy else "waiting"
    level = "full resolution" if frame.level == 1 else f"1/{frame.level} resolution"
    h, w = frame.image.shape[:2]
    if playback_level is not None:
        nxt = "full" if playback_level == 1 else f"1/{playback_level}"
        return (
            f"playback: {level} ({w}x{h}) in {frame.elapsed:.2f} s per frame; following "
            f"the timeline at {nxt} resolution"
        )
    if stale:
        return f"shown: {level} ({w}x{h}) of the previous view; rendering the new one..."
    total = f"{frame.elapsed:.1f} s so far, refining..." if busy else f"{frame.elapsed:.1f} s in all"
    return f"{level} ({w}x{h}): {frame.seconds * 1000:.0f} ms; {total}"


def draw_neural_panel(viewer) -> None:
    """The "Neural render" window's widgets; its status and image follow in
    :func:`late_draw`."""
    nv = viewer.neural
    if nv is None:
        imgui.push_text_wrap_pos(0.0)
        imgui.text_disabled(viewer.neural_absent_reason())
        imgui.pop_text_wrap_pos()
        return
    _, nv.live = imgui.checkbox("Live", nv.live)
    if imgui.is_item_hovered():
        imgui.set_tooltip("re-render whenever the pose or the camera changes")
    imgui.same_line()
    imgui.set_next_item_width(120)
    _, nv.resolution = imgui.slider_int("resolution", nv.resolution, 64, 512, "%d px")
    imgui.same_line()
    force = imgui.button("Render now")
    names = ["checkpoint", *PRESETS]
    imgui.set_next_item_width(120)
    changed, index = imgui.combo("preset", names.index(nv.preset), names)
    if changed:
        nv.set_preset(names[index])
    if imgui.is_item_hovered():
        imgui.set_tooltip("speed/accuracy preset of the render knobs (bench/tradeoff.py)")
    playing = viewer.sequence is not None and viewer.sequence.playing
    viewer.submit_neural(force)  # also done before the panels draw (Viewer.pre_new_frame)
    # the status lines and the image are drawn by late_draw, after the frame's last poll
    # (NeuralView.late_poll): a level that arrives while this frame is built is in it
    line = imgui.get_text_line_height()
    canvas = {
        "draw": imgui.get_window_draw_list(),
        "status": imgui.get_cursor_screen_pos(),
        "playing": playing,
    }
    imgui.dummy(imgui.ImVec2(1.0, line))
    if playing:
        canvas["playback"] = imgui.get_cursor_screen_pos()
        imgui.dummy(imgui.ImVec2(1.0, line))
    for err in list(nv.worker.errors)[-1:]:
        imgui.text_colored(imgui.ImVec4(1.0, 0.45, 0.4, 1.0), err)
    avail = imgui.get_content_region_avail()
    canvas["image"] = (imgui.get_cursor_screen_pos(), avail)
    imgui.dummy(imgui.ImVec2(max(avail.x, 1.0), max(avail.y, 1.0)))  # the image's room
    d = canvas["draw"]
    canvas["clip"] = (d.get_clip_rect_min(), d.get_clip_rect_max())
    nv.canvas = canvas


def late_draw(viewer) -> None:
    """Draw what the Neural render panel left room for (status lines, the image, the stale
    banner) into its window, once :meth:`NeuralView.late_poll` took the frame's newest
    level. A stale image (pose or camera changed since) is dimmed and labelled with the
    pose it shows until the first new level replaces it."""
    nv = viewer.neural
    if nv is None or nv.canvas is None:
        return
    canvas, nv.canvas = nv.canvas, None
    nv.image_rect = None
    draw, playing = canvas["draw"], canvas["playing"]
    text = imgui.get_color_u32(imgui.Col_.text)
    draw.push_clip_rect(*canvas["clip"])
    try:
        draw.add_text(
            canvas["status"],
            text,
            status_line(nv.frame, nv.busy, nv.playback_level if playing else None, nv.stale),
        )
        if "playback" in canvas and nv.frame is not None:
            draw.add_text(
                canvas["playback"],
                imgui.get_color_u32(imgui.Col_.text_disabled),
                f"shows {nv.labels.get(nv.frame.version, 'an earlier frame')}; "
                f"the timeline is at {viewer.pose_label()}",
            )
        line = nv.stale_line()
        if nv.texture is not None:
            nv.image_rect = _draw_image(draw, nv, *canvas["image"], "" if playing else line)
    finally:
        draw.pop_clip_rect()
    viewer.neural_stale_shown = line
    viewer.stale_log.append(line)


def _draw_image(draw, nv, pos, avail, banner: str) -> tuple[float, float, float, float]:
    """The shown level scaled into ``avail`` at ``pos``, dimmed with ``banner`` on top
    when stale; its rectangle (x0, y0, x1, y1)."""
    tw, th = nv.texture.size
    scale = min(avail.x / tw, avail.y / th) if avail.x > 0 and avail.y > 0 else 1.0
    end = imgui.ImVec2(pos.x + tw * scale, pos.y + th * scale)
    tint = imgui.get_color_u32(imgui.ImVec4(*(STALE_TINT if nv.stale else (1, 1, 1, 1))))
    draw.add_image(imgui.ImTextureRef(nv.texture.glo), pos, end, imgui.ImVec2(0, 0), imgui.ImVec2(1, 1), tint)
    if banner:  # within the image, which a preview drawn before the swap covers wholly
        draw.push_clip_rect(pos, end, True)
        draw.add_rect_filled(
            pos, imgui.ImVec2(end.x, pos.y + 22), imgui.get_color_u32(imgui.ImVec4(0.0, 0.0, 0.0, 0.6))
        )
        draw.add_text(
            imgui.ImVec2(pos.x + 6, pos.y + 4), imgui.get_color_u32(imgui.ImVec4(1.0, 0.8, 0.3, 1.0)), banner
        )
        draw.pop_clip_rect()
    return pos.x, pos.y, end.x, end.y
