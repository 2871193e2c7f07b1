"""Progressive neural render in a background thread.

The UI thread :meth:`ProgressiveWorker.submit`s the current pose and camera with the
viewer's version number whenever either changes; the worker renders that job coarse to
fine (1/8, 1/4, 1/2, 1 of the requested size, :func:`texvocab.render.progressive_render`)
and hands each finished level back through :meth:`ProgressiveWorker.poll`. A newer
submission cancels the job in progress once its first level (the preview) is shown: the
version is checked between levels and between ray chunks, and a finer level is
delivered only if its version is still the newest. The preview of a superseded job is
still shown (the panel labels it stale), so a dragged slider shows poses as it goes
instead of none until it stops (``RenderJob.finish_preview``); while it is dragged the
viewer asks for the preview alone (``RenderJob.preview_only``).

Torch in the worker runs with few intra-op threads (``threads``, default 1) so the UI
thread keeps a core for drawing on small machines.
"""

from __future__ import annotations

import os
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from texvocab.pipeline import prepare_shell, progressive_shard

#: render(job, cancelled) -> iterator of (level, rgb (H_l, W_l, 3), seconds[, owned]):
#: ``owned`` (H_l, W_l) bool, the pixels a shard of the job (RenderJob.shard) rendered
#: (absent: all of them)
LevelRenderer = Callable[["RenderJob", Callable[[], bool]], Iterator[tuple[int, object, float]]]


def describe(exc: BaseException) -> str:
    """ "Type: message (file:line)" of the innermost frame, for the panel."""
    where = traceback.extract_tb(exc.__traceback__)[-1]
    return f"{type(exc).__name__}: {exc} ({Path(where.filename).name}:{where.lineno})"


def cpu_seconds(stat: str) -> float:
    """CPU seconds (user + system) from a Linux ``/proc/.../stat`` file; 0 if unreadable."""
    try:
        with open(stat) as f:
            fields = f.read().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


@dataclass(frozen=True)
class RenderJob:
    """One request: the viewer ``version`` it belongs to, pose (24, 3) axis-angle, trans
    (3,), and a :class:`texvocab.capture.Camera` at the full target size."""

    version: int
    pose: np.ndarray
    trans: np.ndarray
    camera: object
    march: object = None  # MarchSettings for this job (None: the renderer's own)
    levels: tuple[int, ...] | None = None  # downscale factors to render (None: the renderer's)
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)  # RGB in [0, 1] behind the body
    #: a newer job does not cancel this one's first level, which is finished and shown:
    #: while a slider is dragged, each pose would otherwise be cancelled before anything
    #: of it reached the screen
    finish_preview: bool = True
    #: this job is share ``shard`` of ``shards`` of the view (texvocab_viewer.neural.render_process splits a
    #: view over processes; texvocab.render.progressive_shard)
    shard: int = 0
    shards: int = 1
    #: a shard after the first starts once the first has sent this job's preview
    after_preview: bool = False
    #: render the first level (the preview) and stop: while a slider is dragged each pose
    #: is superseded a frame later, and a finer level of it would only delay the next
    #: pose's preview (NeuralView submits the full render once the pose rests)
    preview_only: bool = False


@dataclass(frozen=True)
class RenderFrame:
    """One delivered level: ``image`` (H, W, 3) float32 in [0, 1]; ``level`` the
    downscale factor (8, 4, 2, 1); ``seconds`` the wall time of this level;
    ``elapsed`` since the job was picked up (all levels so far)."""

    version: int
    level: int
    image: np.ndarray
    seconds: float
    elapsed: float


def model_renderer(model, march, levels=(8, 4, 2, 1)) -> LevelRenderer:
    """A :data:`LevelRenderer` for a trained avatar: per-pose context and shell built
    once (the shell only when needed), then the levels (as
    :func:`texvocab.pipeline.evaluate.render_view` does for one), of the job's shard.
    Every key's feature maps are encoded up front (``PoseFeature.warm_feature_maps``).

    A job whose first level is the preview (every job of an unsplit render, the first
    shard's of a split one) builds its surface index on the previous job's slot layout
    (``SurfaceIndex(like=...)``: 3 of the context's 8 ms, the same answers) and splits
    its own once the first level is out, if a finer level follows."""
    with torch.no_grad():
        model.pose_feature.warm_feature_maps()
    previous = [None]  # the last job's surface index: its slot layout is lent

    def render(job: RenderJob, cancelled: Callable[[], bool]):
        m = job.march or march
        borrow = job.shard == 0
        count = len(job.levels or levels)
        with torch.no_grad():
            ctx = model.pose_feature.context(job.pose, job.trans, like=previous[0] if borrow else None)
            previous[0] = ctx.index
            if cancelled():
                return

            # the surface-guided marcher builds what it needs of it (the bounding balls
            # for its residual rays, the grid if a ray falls back to marching) after the
            # first, preview level; the shell marcher needs it at once (its render path)
            shell = prepare_shell(m, ctx.vertices, model.body.faces, ctx.index)
            field = model.for_pose(ctx, m.precision)
        for i, out in enumerate(
            progressive_shard(
                field,
                job.camera,
                ctx.vertices,
                model.body.faces,
                m,
                levels=job.levels or levels,
                cancelled=cancelled,
                background=job.background,
                shell=shell,
                index=ctx.index,
                shard=(job.shard, job.shards),
            )
        ):
            yield out
            if job.preview_only:
                return
            if i + 1 < count:  # a finer level follows: it searches this pose's own split
                ctx.index.relayout()

    return render


class DeliveredLevels:
    """What the UI reads of a render worker, thread or process: the newest delivered
    level (:meth:`poll`, :attr:`latest`), whether the newest job is still running
    (:attr:`busy`), the delivered (version, level) pairs and the errors. The worker
    writes ``_frame``, ``_fresh``, ``_busy`` under ``_lock``."""

    def __init__(self):
        self._lock = threading.Lock()
        self._version = -1
        self._frame: RenderFrame | None = None
        self._fresh = False
        self._arrived = threading.Condition(self._lock)  # notified per level and at the end
        self._busy = False
        self.delivered: deque[tuple[int, int]] = deque(maxlen=256)  # (version, level), in order
        self.errors: deque[str] = deque(maxlen=16)  # "Type: message (file:line)"
        self.last_traceback = ""

    def poll(self) -> RenderFrame | None:
        """The newest delivered level if not returned before, else None."""
        with self._lock:
            if not self._fresh:
                return None
            self._fresh = False
            return self._frame

    def wait_for(self, version: int, timeout: float) -> bool:
        """Block until a level of job ``version`` (or a newer job) is delivered, for at
        most ``timeout`` seconds, and not once the worker is idle (done or failed). True
        if one was."""
        deadline = time.perf_counter() + timeout
        with self._arrived:
            while self._frame is None or self._frame.version < version:
                left = deadline - time.perf_counter()
                if left <= 0 or not self._busy:
                    return False
                self._arrived.wait(left)
            return True

    @property
    def latest(self) -> RenderFrame | None:
        with self._lock:
            return self._frame

    @property
    def busy(self) -> bool:
        """True from a submission until its finest level is delivered (or it fails)."""
        with self._lock:
            return self._busy


class ProgressiveWorker(DeliveredLevels):
    """Background thread rendering the newest :class:`RenderJob` level by level.

    ``render`` yields ``(level, rgb, seconds)`` and must stop soon after its
    ``cancelled()`` argument returns True (progressive_render does, between levels and
    ray chunks). ``threads``: torch intra-op threads for the worker (None: unchanged).
    ``nice``: raise the thread's niceness by this much (Linux) so drawing comes first.
    ``on_frame``: called (from the worker thread) after each delivered level, e.g. to wake
    an idling UI so it shows the level at once (hello_imgui.request_refresh).
    """

    in_process = True  # its CPU time is part of the viewer process's

    def __init__(
        self,
        render: LevelRenderer,
        threads: int | None = 1,
        nice: int = 0,
        on_frame: Callable[[], None] | None = None,
    ):
        super().__init__()
        self._render = render
        self._on_frame = on_frame
        self._threads = threads
        self._nice = nice
        self._wake = threading.Condition(self._lock)
        self._job: RenderJob | None = None
        self._stop = False
        self.native_id: int | None = None
        self._thread = threading.Thread(target=self._run, name="texvocab-neural", daemon=True)
        self._thread.start()

    # --- UI thread --------------------------------------------------------------------
    def submit(self, job: RenderJob) -> None:
        """Make ``job`` the newest request, cancelling older work; a version already
        submitted is ignored (the caller bumps the version on every change)."""
        with self._wake:
            if job.version == self._version:
                return
            self._version = job.version
            self._job = job
            self._busy = True
            self._wake.notify()

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def cpu_seconds(self) -> float:
        """CPU seconds the render thread has used (Linux /proc; 0 elsewhere)."""
        if self.native_id is None:
            return 0.0
        return cpu_seconds(f"/proc/self/task/{self.native_id}/stat")

    def stop(self, timeout: float = 10.0) -> bool:
        """Cancel any work and join the thread; True if it ended within ``timeout``."""
        with self._wake:
            self._stop = True
            self._version += 1  # cancels the job in progress
            self._wake.notify()
        self._thread.join(timeout)
        return not self._thread.is_alive()

    # --- worker thread ----------------------------------------------------------------
    def _run(self) -> None:
        if self._threads is not None:
            torch.set_num_threads(self._threads)
        self.native_id = threading.get_native_id()
        if self._nice:
            try:  # Linux: a thread is a task with its own niceness
                current = os.getpriority(os.PRIO_PROCESS, self.native_id)
                os.setpriority(os.PRIO_PROCESS, self.native_id, min(current + self._nice, 19))
            except (AttributeError, OSError):
                pass
        while True:
            with self._wake:
                while self._job is None and not self._stop:
                    self._wake.wait()
                if self._stop:
                    return
                job, self._job = self._job, None
            self._render_job(job)

    def _stale(self, job: RenderJob) -> bool:
        return self._stop or job.version != self._version  # int read: atomic under the GIL

    def _render_job(self, job: RenderJob) -> None:
        start = time.perf_counter()
        shown = not job.finish_preview  # until its first level is shown, a job is not cancelled

        def cancelled() -> bool:
            return self._stop or (shown and self._stale(job))

        try:
            for level, rgb, seconds, *_ in self._render(job, cancelled):
                image = np.ascontiguousarray(np.asarray(rgb, dtype=np.float32))
                frame = RenderFrame(
                    job.version, int(level), image, float(seconds), time.perf_counter() - start
                )
                with self._lock:
                    if cancelled():
                        return
                    self._frame, self._fresh = frame, True
                    self.delivered.append((job.version, int(level)))
                    self._arrived.notify_all()
                shown = True
                if self._on_frame is not None:
                    self._on_frame()
                if self._stale(job):  # a newer job waits: the preview was its due
                    return
        except Exception as exc:  # shown in the panel; the worker keeps serving
            self.last_traceback = traceback.format_exc()
            with self._lock:
                self.errors.append(describe(exc))
        finally:
            with self._lock:
                if not self._stale(job) and self._job is None:
                    self._busy = False
                self._arrived.notify_all()  # a UI waiting for a level stops waiting
            if self._on_frame is not None:
                self._on_frame()  # the UI shows "done" (or the error) without waiting
