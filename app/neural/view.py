"""The neural render's state behind its panel: the worker (a render process of its own,
:mod:`texvocab_viewer.neural.render_process`, or a thread, :mod:`texvocab_viewer.neural.worker`),
the versions of the views it was asked for and what each shows, the level on screen as a
GL texture, playback's level, and the preview a pose-changing frame waits for. The panel
that draws it is :mod:`texvocab_viewer.panels.neural`."""

from __future__ import annotations

import time
from collections import deque
from dataclasses import replace

import numpy as np

from texvocab.pipeline import march_settings, render_overrides
from texvocab_viewer.arguments import NEURAL_PREVIEW_WAIT_MS
from texvocab_viewer.neural.render_process import ProcessWorker
from texvocab_viewer.neural.worker import ProgressiveWorker, RenderFrame, RenderJob, model_renderer

#: during playback the render follows the timeline at one level: a finer one when a
#: frame took under half this many seconds, a coarser one when it took more
PLAYBACK_SECONDS = 0.5
#: a submission follows a pause when the one before is at least this many seconds older:
#: its frame waits for the preview (NeuralView.preview_wait) and the job renders every
#: level. Poses that stream in faster, as under a dragged slider, are rendered as
#: previews alone, each frame waiting for its own until it must end (Viewer.before_swap,
#: DRAG_FRAME_MS); the first frame without a change submits the full render of the pose
#: it rests at.
PREVIEW_PAUSE = 0.25
#: the levels of a dragged pose's full render once it rests: its preview level, then the
#: full one (each level after the preview is a pass of its own over the field, with the
#: per-call cost that carries: levels 4 and 2 between would delay the full level)
REST_LEVELS = (8, 1)


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
        #: a dragged pose's full render once it rests: None, its preview (if it is not
        #: shown yet) and the full level; or the levels to render (bench/viewer_ui.py's
        #: --rest-levels 8,4,2,1 times the former behaviour)
        self.rest_levels: tuple[int, ...] | None = None
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
        #: (version, deadline, while dragging) of the preview this frame waits for
        self._await: tuple[int, float, bool] | None = None
        self._last_job: tuple[tuple, RenderJob] | None = None  # (view, job) submitted last
        self._changed = False  # a job was submitted in this frame (before late_poll)
        self._playing = False
        #: where draw_neural_panel left room for the status line and the image (late_draw)
        self.canvas: dict | None = None
        #: where late_draw put the image this frame: x0, y0, x1, y1 (None: not drawn)
        self.image_rect: tuple[float, float, float, float] | None = None
        #: the level this frame draws (late_draw's, or the preview drawn over it before
        #: the swap): what is on screen once the frame is swapped
        self.on_screen: RenderFrame | None = None

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
        now = time.perf_counter()
        if changed and not wait:
            self._key = key
            self._playback_job = playing
            dragged = not playing and not force and now - self._submitted_at < PREVIEW_PAUSE
            self._submitted_at = now
            waits = not playing and self.preview_wait > 0
            deadline = now + self.preview_wait if not dragged else np.inf  # dragged: the frame's
            wait = (deadline, dragged) if waits else None
            self._submit(view, self._job(state, camera, w, h, view, playing, dragged), wait)
        self._playing = playing
        if poll:
            self._take(self.worker.poll())

    def _job(self, state, camera, w: int, h: int, view: tuple, playing: bool, dragged: bool) -> RenderJob:
        """The job of ``view``: playback's one level, a dragged pose's preview alone, or
        every level; its version is set by :meth:`_submit`."""
        return RenderJob(
            0,
            state.pose.copy(),
            state.trans.copy(),
            camera.to_texvocab_camera(w, h),
            self.march,
            (self.playback_level,) if playing else None,
            view[5],
            # playback renders one level and is never cancelled by the timeline anyway
            finish_preview=not playing,
            preview_only=dragged,
        )

    def _submit(self, view: tuple, job: RenderJob, wait: tuple[float, bool] | None) -> None:
        """Submit ``job`` (of ``view``) as a new version; ``wait``: (deadline, while
        dragging) of this frame's wait for its preview, or None."""
        self.version += 1
        self.labels[self.version] = self._current_label
        self.keys[self.version] = view  # pose, camera, size, preset, background
        for old in [v for v in self.labels if v < self.version - 64]:
            del self.labels[old], self.keys[old]
        self._await = None if wait is None else (self.version, *wait)
        self._last_job = (view, replace(job, version=self.version))
        self._changed = True
        self.worker.submit(self._last_job[1])

    def _rest(self) -> None:
        """Once per frame (late_poll): when the last job is a dragged pose's preview alone
        and this frame changed nothing, the pose rests (the slider was let go, or holds
        still): submit its full render. Its preview is not finished if a newer pose
        comes: that pose's preview is on screen or on its way."""
        changed, self._changed = self._changed, False
        last = self._last_job
        if changed or last is None or not last[1].preview_only or not self.live or self._playing:
            return
        if last[0] != self._current:
            return  # the view moved on without a submission
        # the pose's preview is on screen (or on its way: then a preview first): the full
        # level at once, one pass over the rest of the pixels, not the levels between
        shown = self.frame is not None and self.frame.version == last[1].version
        levels = self.rest_levels or ((1,) if shown else REST_LEVELS)
        self._submit(last[0], replace(last[1], preview_only=False, finish_preview=False, levels=levels), None)

    def _take(self, frame: RenderFrame | None) -> None:
        if frame is not None:
            self._upload(frame)
            if self._playing:
                self._adapt_playback_level(frame)

    def late_poll(self) -> None:
        """After the frame's panels, before ImGui draws: take the newest level, so one
        that arrived while the frame was built is in it (:func:`late_draw`). A preview this
        frame was to wait for that came so counts as a wait of 0 s."""
        self._rest()
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

    def wait_preview(self, drag_until: float = -np.inf) -> bool:
        """After ImGui drew the frame, before the swap: if :attr:`awaiting`, wait for the
        pose's preview until ``preview_wait`` seconds after its submission (while a slider
        is dragged: until ``drag_until``, a perf_counter time the frame must end by) and
        take it. True when a level to draw over the frame was taken: one of the pose, or
        while dragging any newer than the frame drew (the previous pose's preview, one
        frame old, rather than none)."""
        if not self.awaiting:
            self._await = None
            return False
        (version, deadline, dragged), self._await = self._await, None
        if dragged:
            deadline = drag_until
        start = time.perf_counter()
        came = self.worker.wait_for(version, deadline - start)
        self.waits.append((version, time.perf_counter() - start, came))
        frame = self.worker.poll()
        self._take(frame)
        return frame is not None and (frame.version >= version or dragged)

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

    def stale_reason(self) -> str:
        """Why the shown image is stale, in a few words: "pose edited since", "camera
        moved since" or "view changed since" (its size, preset or background); "" when
        it is current."""
        if not self.stale:
            return ""
        shown = self.keys.get(self.frame.version)
        if shown is None or self._current is None or shown[0] != self._current[0]:
            return "pose edited since"
        if shown[1] != self._current[1]:
            return "camera moved since"
        return "view changed since"

    def stale_tooltip(self) -> str:
        """The stale banner's whole text: :meth:`stale_line`, then which pose the image
        shows and which pose is current ("" when the image is current)."""
        line = self.stale_line()
        if not line:
            return ""
        shown = self.labels.get(self.frame.version, "an older pose")
        return f"{line}\nshown: {shown}\ncurrent: {self._current_label or 'the new pose'}"

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
