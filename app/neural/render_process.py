"""The viewer's neural render worker in a process of its own (the default; the thread
worker, :class:`texvocab_viewer.neural.worker.ProgressiveWorker`, stays selectable with
``--neural-worker thread``).

Why a process: the render and the UI are both mostly Python between small native
operations, and in one interpreter they take turns holding the GIL. Measured under
Xvfb (bench/viewer_ui.py): outside the window a pose's first level took
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
  :func:`texvocab_viewer.neural.worker.model_renderer` with the trained model; the
  arguments come on a pipe of their own, sent from a thread, so the children start
  side by side and the window does not wait for them), runs torch with
  ``threads`` intra-op threads at niceness +``nice``, and ends when the viewer sends
  None or closes the pipe (the viewer exited or crashed).
- With ``processes`` > 1, each child renders one share of every job
  (``RenderJob.shard``, :func:`texvocab.render.progressive_shard`: the preview is
  shard 0's alone, later levels' pixels go round the shards) and sends the pixels it
  owns with each level; the listener merges them and delivers a level once every
  shard has sent it. Shards after the first run at ``SHARD_NICE`` more niceness, so
  while the UI holds one core the preview's shard gets most of the other; and they
  start a job only once its preview is sent (``after_preview``). bench/render_worker.py
  (no window, 1 torch thread per process, 256x132): a full level in 0.577 s in one
  process, 0.412 s in two. A preview-only job (``RenderJob.preview_only``, a dragged
  slider's) goes to the first shard alone.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import pickle
import signal
import sys
import threading
import time
import traceback
from dataclasses import replace
from multiprocessing.connection import wait

import numpy as np
import torch

from texvocab.pipeline import budget_blas_threads
from texvocab_viewer.neural.worker import DeliveredLevels, RenderFrame, RenderJob, cpu_seconds, describe

#: spawn, not fork: a forked child would inherit the window's GL context and torch's
#: thread pools in whatever state they are in
_SPAWN = mp.get_context("spawn")


def _newest_job(jobs, job):
    """``job`` or, if more are waiting in the pipe, the last of them (None: stop)."""
    while job is not None and jobs.poll():
        job = jobs.recv()
    return job


def _serve_then_exit(*args) -> None:
    """:func:`_serve`, then the process ends without the interpreter's teardown (torch's
    takes about a second on a loaded machine, and the viewer's close waits for it);
    nothing is left to flush but the standard streams. An exception still ends it as
    one (its exit code says so)."""
    _serve(*args)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


def _serve(factory, setup, threads: int | None, nice: int, jobs, results, newest, previewed) -> None:
    """The child process: build the renderer from the pickled ``factory`` arguments that
    arrive on ``setup`` (the viewer sends them once the child runs), then render the newest job, level by
    level, until told to stop (None) or the viewer's end of ``jobs`` closes. A shard
    after the first starts a job with a preview only once the first shard is past it
    (``previewed``: the last such version): while a slider is dragged each pose is
    cancelled after its preview, and the other shards' work on it would be wasted.
    Ctrl-C in the terminal reaches the whole process group: the viewer answers it (one
    line, texvocab.cli.interrupts) and this child, ignoring it, ends when its pipe closes."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if nice:
        try:
            os.nice(nice)
        except OSError:
            pass
    if threads is not None:
        torch.set_num_threads(threads)
    budget_blas_threads(threads or 1)  # numpy's OpenBLAS threads would spin between calls
    try:
        args = setup.recv_bytes()
        setup.close()
    except (EOFError, OSError):
        return  # the viewer is gone before the child could start
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
        while job.after_preview and previewed.value < job.version == newest.value:
            time.sleep(0.001)
        if job.version != newest.value:
            results.send(("done", job.version))
            continue
        start = time.perf_counter()
        shown = [not job.finish_preview]  # as the thread: the preview is not cancelled

        def stale(version=job.version) -> bool:
            return newest.value != version

        def cancelled() -> bool:
            return newest.value < 0 or (shown[0] and stale())

        try:
            for level, rgb, seconds, *owned in render(job, cancelled):
                image = np.ascontiguousarray(np.asarray(rgb, dtype=np.float32))
                mask = np.asarray(owned[0], dtype=bool) if owned else None
                if cancelled():
                    break
                results.send(
                    (
                        "level",
                        job.version,
                        int(level),
                        image,
                        float(seconds),
                        time.perf_counter() - start,
                        not shown[0],
                        mask,
                    )
                )
                shown[0] = True
                previewed.value = max(previewed.value, job.version)
                if stale():
                    break
        except (BrokenPipeError, EOFError):
            return
        except Exception as exc:  # shown in the panel; the process keeps serving
            results.send(("error", job.version, describe(exc), traceback.format_exc()))
        finally:
            previewed.value = max(previewed.value, job.version)  # or it never comes
        results.send(("done", job.version))


def _feed(setups: list, blob: bytes) -> None:
    """Send the renderer's pickled arguments to each child in turn, then close the pipes
    (a child that died before reading is reported by the listener, not here)."""
    for setup in setups:
        try:
            setup.send_bytes(blob)
        except (BrokenPipeError, OSError):
            pass
        finally:
            setup.close()


#: niceness added to the render processes after the first (see the module docstring)
SHARD_NICE = 5


class ProcessWorker(DeliveredLevels):
    """Render processes with the interface of :class:`texvocab_viewer.neural.worker.ProgressiveWorker`
    (submit, poll, latest, busy, alive, stop, delivered, errors, last_traceback,
    cpu_seconds).

    ``factory(*args)`` must return a :data:`texvocab_viewer.neural.worker.LevelRenderer`; both are pickled
    into each child (``factory`` by its module path). ``threads``: torch intra-op threads
    of a child; ``nice``: its niceness increment; ``processes``: how many children split
    each job (see the module docstring); ``on_frame``: called from a listener thread
    after each delivered level and when a job ends.
    """

    in_process = False  # its CPU time is not the viewer process's

    def __init__(
        self,
        factory,
        args: tuple = (),
        threads: int | None = 1,
        nice: int = 0,
        on_frame=None,
        processes: int = 1,
    ):
        super().__init__()
        self._on_frame = on_frame
        self._newest = _SPAWN.RawValue("q", -1)
        self._previewed = _SPAWN.RawValue("q", -1)  # written by the first shard only
        self._jobs, self._results, self._processes = [], [], []
        blob, setups = pickle.dumps(tuple(args)), []
        for k in range(max(1, int(processes))):
            child_jobs, jobs = _SPAWN.Pipe(duplex=False)
            results, child_results = _SPAWN.Pipe(duplex=False)
            child_setup, setup = _SPAWN.Pipe(duplex=False)
            proc = _SPAWN.Process(
                target=_serve_then_exit,
                name=f"texvocab-neural-{k}",
                daemon=True,
                args=(
                    factory,
                    child_setup,
                    threads,
                    min(nice + (SHARD_NICE if k else 0), 19),
                    child_jobs,
                    child_results,
                    self._newest,
                    self._previewed,
                ),
            )
            proc.start()
            child_jobs.close()  # the child's ends: only the child holds them now, so
            child_results.close()  # either side sees EOF when the other goes away
            child_setup.close()
            setups.append(setup)
            self._jobs.append(jobs)
            self._results.append(results)
            self._processes.append(proc)
        self.pid = self._processes[0].pid
        self.pids = [p.pid for p in self._processes]
        self._merge: dict = {}  # the newest job's levels as its shards send them
        self._listener = threading.Thread(target=self._listen, name="texvocab-neural-results", daemon=True)
        self._listener.start()
        # the model goes to the children from a thread: a pipe takes a large message only
        # as fast as its reader reads, and a child reads once it has imported torch, so
        # sending it here would hold the window for each child's start-up in turn
        self._feeder = threading.Thread(
            target=_feed, args=(setups, blob), name="texvocab-neural-setup", daemon=True
        )
        self._feeder.start()

    # --- UI thread --------------------------------------------------------------------
    def submit(self, job: RenderJob) -> None:
        """Make ``job`` the newest request, cancelling older work; a version already
        submitted is ignored."""
        n = len(self._jobs)
        with self._lock:
            if job.version == self._version:
                return
            self._version, self._busy = job.version, True
            size = None if n == 1 else (job.camera.height, job.camera.width)
            if job.preview_only:  # the preview is the first shard's alone (module docstring)
                n = 1
            self._merge = {"size": size, "canvas": None, "got": {}, "sent": set(), "done": set(), "shards": n}
        self._newest.value = job.version  # the other shards drop what they were doing
        try:
            for k, jobs in enumerate(self._jobs[:n]):
                jobs.send(
                    job
                    if n == 1
                    else replace(
                        job,
                        shard=k,
                        shards=n,
                        finish_preview=job.finish_preview and k == 0,
                        after_preview=job.finish_preview and k > 0,
                    )
                )
        except (BrokenPipeError, OSError) as exc:
            self._ended(f"the render process is gone ({type(exc).__name__})")

    @property
    def alive(self) -> bool:
        return any(p.is_alive() for p in self._processes)

    def cpu_seconds(self) -> float:
        """CPU seconds the render processes have used (Linux /proc; 0 elsewhere)."""
        return sum(cpu_seconds(f"/proc/{pid}/stat") for pid in self.pids)

    def stop(self, timeout: float = 10.0) -> bool:
        """Cancel any work and end the processes; True if they ended by themselves within
        ``timeout`` (otherwise they are terminated)."""
        self._newest.value = -2  # cancels the job in progress
        for jobs in self._jobs:
            try:
                jobs.send(None)
            except (BrokenPipeError, OSError):
                pass
        deadline = time.monotonic() + timeout
        clean = True
        for proc in self._processes:
            # join can return while the child is still exiting (its sentinel closes before
            # it can be reaped): wait on until it is reaped or the deadline passes
            while proc.is_alive() and time.monotonic() < deadline:
                proc.join(min(0.05, max(0.0, deadline - time.monotonic())))
            if proc.is_alive():
                clean = False
                proc.terminate()
                proc.join(2.0)
        for jobs in self._jobs:
            jobs.close()
        self._feeder.join(2.0)
        self._listener.join(2.0)
        return clean

    # --- listener thread --------------------------------------------------------------
    def _listen(self) -> None:
        shard_of = {id(c): k for k, c in enumerate(self._results)}
        open_pipes = list(self._results)
        while open_pipes:
            for conn in wait(open_pipes):
                try:
                    message = conn.recv()
                except (EOFError, OSError):
                    open_pipes.remove(conn)
                    self._gone(self._processes[shard_of[id(conn)]])
                    continue
                if self._take(message, shard_of[id(conn)]) and self._on_frame is not None:
                    self._on_frame()

    def _gone(self, proc) -> None:
        """A child's pipe closed: reap it to read its exit code (without the join, a crash
        was reported as "exit code None") and say so unless it was told to stop."""
        proc.join(2.0)
        code = proc.exitcode
        if code not in (0, None) or self.busy:
            self._ended(f"the render process ended (exit code {code})")

    def _take(self, message: tuple, shard: int) -> bool:
        """Keep a child's message; True when the UI should look (a level, an error, the
        newest job done)."""
        kind, version = message[0], message[1]
        n = len(self._results)
        with self._lock:
            current = version == self._version
            if kind == "error":
                self.errors.append(message[2])
                self.last_traceback = message[3]
                return True
            if kind == "done":
                if current:
                    self._merge["done"].add(shard)
                    self._busy = len(self._merge["done"]) < self._merge["shards"]
                    self._arrived.notify_all()  # a UI waiting for a level stops waiting
                return current and not self._busy
            _, _, level, image, seconds, elapsed, preview, owned = message
            if preview and (current or self._frame is None or version > self._frame.version):
                self._deliver(version, level, image, seconds, elapsed)  # shard 0's alone
                if current:
                    self._merge["sent"].add(level)
                return True
            if not current:
                return False
            if n == 1 or owned is None:
                self._deliver(version, level, image, seconds, elapsed)
                return True
            return self._merge_level(version, level, image, seconds, elapsed, owned, shard)

    def _merge_level(self, version, level, image, seconds, elapsed, owned, shard) -> bool:
        """Write a shard's owned pixels of a level into the newest job's canvas; deliver
        the level once every shard sent it (under ``_lock``)."""
        m = self._merge
        if m["canvas"] is None:
            m["canvas"] = np.zeros((*m["size"], 3), np.float32)
        view = m["canvas"][::level, ::level]
        view[owned] = image[owned]
        got = m["got"].setdefault(level, [0, 0.0, 0.0])
        got[0] += 1
        got[1], got[2] = max(got[1], seconds), max(got[2], elapsed)
        if got[0] < len(self._results) or level in m["sent"]:
            return False
        m["sent"].add(level)
        self._deliver(version, level, view.copy(), got[1], got[2])
        return True

    def _deliver(self, version, level, image, seconds, elapsed) -> None:
        self._frame = RenderFrame(version, level, image, seconds, elapsed)
        self._fresh = True
        self.delivered.append((version, level))
        self._arrived.notify_all()

    def _ended(self, why: str) -> None:
        with self._lock:
            if self._busy:
                self.errors.append(why)
            self._busy = False
            self._arrived.notify_all()
        if self._on_frame is not None:
            self._on_frame()
