"""The viewer's neural render worker in a process of its own (the default; the thread
worker, :class:`app.worker.ProgressiveWorker`, stays selectable with
``--neural-worker thread``).

Why a process: the render and the UI are both mostly Python between small native
operations, and in one interpreter they take turns holding the GIL. Measured under
Xvfb (bench/viewer_ui.py, session 11): outside the window a pose's first level took
36-50 ms on one thread, inside it 117-151 ms, and the full level 0.5-0.6 s against
0.68-0.89 s; the render thread got 0.71 of a core while the UI thread ran. In a process
of its own the render holds its own interpreter, and the UI thread holds the window's.

The same protocol as the thread worker, over two pipes and one shared integer:

- :meth:`ProcessWorker.submit` stores the job's version in shared memory (``newest``)
  and sends the job. The child renders only the newest job it has received, and its
  ``cancelled()`` compares that job's version with ``newest``, so a newer submission
  stops the job in progress between ray chunks once its first level (the preview) is
  sent, as in the thread (``RenderJob.finish_preview``).
- The child sends each finished level, ``("level", version, level, image, seconds,
  elapsed, preview)``, then ``("done", version)`` (after ``("error", ...)`` if the
  render raised). A listener thread in the viewer keeps a level if its version is
  still the newest, or if it is the preview of a job newer than the image shown, and
  calls ``on_frame`` to wake the UI.
- The child loads the renderer from ``factory(*args)`` (pickled: for the viewer,
  :func:`app.worker.model_renderer` with the trained model), runs torch with
  ``threads`` intra-op threads at niceness +``nice``, and ends when the viewer sends
  None or closes the pipe (the viewer exited or crashed).
"""
from __future__ import annotations

import multiprocessing as mp
import os
import pickle
import threading
import time
import traceback

import numpy as np

from app.worker import DeliveredLevels, RenderFrame, RenderJob, cpu_seconds, describe

#: spawn, not fork: a forked child would inherit the window's GL context and torch's
#: thread pools in whatever state they are in
_SPAWN = mp.get_context("spawn")


def _newest_job(jobs, job):
    """``job`` or, if more are waiting in the pipe, the last of them (None: stop)."""
    while job is not None and jobs.poll():
        job = jobs.recv()
    return job


def _serve(factory, args: bytes, threads: int | None, nice: int, jobs, results,
           newest) -> None:
    """The child process: build the renderer, then render the newest job, level by
    level, until told to stop (None) or the viewer's end of ``jobs`` closes."""
    if nice:
        try:
            os.nice(nice)
        except OSError:
            pass
    import torch

    from texvocab.pipeline import budget_blas_threads

    if threads is not None:
        torch.set_num_threads(threads)
    budget_blas_threads(threads or 1)  # numpy's OpenBLAS threads would spin between calls
    try:
        render = factory(*pickle.loads(args))
    except Exception as exc:  # e.g. a model that does not load here: say so, then stop
        results.send(("error", -1, describe(exc), traceback.format_exc()))
        return
    while True:
        try:
            job = _newest_job(jobs, jobs.recv())
        except (EOFError, OSError):
            return
        if job is None:
            return
        if job.version != newest.value:  # superseded before it started
            continue
        start = time.perf_counter()
        shown = [not job.finish_preview]  # as the thread: the preview is not cancelled

        def stale(version=job.version) -> bool:
            return newest.value != version

        def cancelled() -> bool:
            return newest.value < 0 or (shown[0] and stale())
        try:
            for level, rgb, seconds in render(job, cancelled):
                image = np.ascontiguousarray(np.asarray(rgb, dtype=np.float32))
                if cancelled():
                    break
                results.send(("level", job.version, int(level), image, float(seconds),
                              time.perf_counter() - start, not shown[0]))
                shown[0] = True
                if stale():
                    break
        except (BrokenPipeError, EOFError):
            return
        except Exception as exc:  # shown in the panel; the process keeps serving
            results.send(("error", job.version, describe(exc), traceback.format_exc()))
        results.send(("done", job.version))


class ProcessWorker(DeliveredLevels):
    """A render process with the interface of :class:`app.worker.ProgressiveWorker`
    (submit, poll, latest, busy, alive, stop, delivered, errors, last_traceback,
    cpu_seconds).

    ``factory(*args)`` must return a :data:`app.worker.LevelRenderer`; both are pickled
    into the child (``factory`` by its module path). ``threads``: torch intra-op threads
    of the child; ``nice``: its niceness increment; ``on_frame``: called from a listener
    thread after each delivered level and when a job ends.
    """

    in_process = False  # its CPU time is not the viewer process's

    def __init__(self, factory, args: tuple = (), threads: int | None = 1, nice: int = 0,
                 on_frame=None):
        super().__init__()
        self._on_frame = on_frame
        self._newest = _SPAWN.RawValue("q", -1)
        child_jobs, self._jobs = _SPAWN.Pipe(duplex=False)
        self._results, child_results = _SPAWN.Pipe(duplex=False)
        self._process = _SPAWN.Process(
            target=_serve, name="texvocab-neural", daemon=True,
            args=(factory, pickle.dumps(tuple(args)), threads, nice, child_jobs, child_results,
                  self._newest))
        self._process.start()
        child_jobs.close()  # the child's ends: only the child holds them now, so either
        child_results.close()  # side sees EOF when the other goes away
        self.pid = self._process.pid
        self._listener = threading.Thread(target=self._listen, name="texvocab-neural-results",
                                          daemon=True)
        self._listener.start()

    # --- UI thread --------------------------------------------------------------------
    def submit(self, job: RenderJob) -> None:
        """Make ``job`` the newest request, cancelling older work; a version already
        submitted is ignored."""
        with self._lock:
            if job.version == self._version:
                return
            self._version, self._busy = job.version, True
        self._newest.value = job.version
        try:
            self._jobs.send(job)
        except (BrokenPipeError, OSError) as exc:
            self._ended(f"the render process is gone ({type(exc).__name__})")

    @property
    def alive(self) -> bool:
        return self._process.is_alive()

    def cpu_seconds(self) -> float:
        """CPU seconds the render process has used (Linux /proc; 0 elsewhere)."""
        return cpu_seconds(f"/proc/{self.pid}/stat")

    def stop(self, timeout: float = 10.0) -> bool:
        """Cancel any work and end the process; True if it ended by itself within
        ``timeout`` (otherwise it is terminated)."""
        self._newest.value = -2  # cancels the job in progress
        try:
            self._jobs.send(None)
        except (BrokenPipeError, OSError):
            pass
        self._process.join(timeout)
        clean = not self._process.is_alive()
        if not clean:
            self._process.terminate()
            self._process.join(2.0)
        self._jobs.close()
        self._listener.join(2.0)
        return clean

    # --- listener thread --------------------------------------------------------------
    def _listen(self) -> None:
        while True:
            try:
                message = self._results.recv()
            except (EOFError, OSError):
                # the pipe closes while the process is still exiting: reap it to read its
                # exit code (without the join, a crash was reported as "exit code None")
                self._process.join(2.0)
                code = self._process.exitcode
                if code not in (0, None) or self.busy:
                    self._ended(f"the render process ended (exit code {code})")
                return
            kind, version = message[0], message[1]
            with self._lock:
                current = version == self._version
                preview = kind == "level" and message[6] and (
                    self._frame is None or version > self._frame.version)
                if kind == "level" and (current or preview):
                    _, _, level, image, seconds, elapsed, _ = message
                    self._frame = RenderFrame(version, level, image, seconds, elapsed)
                    self._fresh = True
                    self.delivered.append((version, level))
                elif kind == "error":
                    self.errors.append(message[2])
                    self.last_traceback = message[3]
                elif kind == "done" and current:
                    self._busy = False
            if self._on_frame is not None and (current or preview or kind == "error"):
                self._on_frame()

    def _ended(self, why: str) -> None:
        with self._lock:
            if self._busy:
                self.errors.append(why)
            self._busy = False
        if self._on_frame is not None:
            self._on_frame()
