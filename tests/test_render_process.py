"""The viewer's render process (app/render_process.py): the thread worker's protocol
across a process boundary. Levels arrive coarse to fine from another process, a newer
version cancels the job in progress and stale levels never arrive, a failing render is
reported and the process keeps serving, a crashed process is reported, and stop ends it.
The renderers are module-level factories: the child imports this module to build them."""
from __future__ import annotations

import os
import time

import numpy as np
import pytest

from app.render_process import ProcessWorker
from app.worker import RenderJob


def _levels(job, cancelled, levels=(8, 4, 2, 1)):
    for level in levels:
        if cancelled():
            return
        image = np.full((max(1, 16 // level), max(1, 16 // level), 3), job.version / 10,
                        np.float32)
        yield level, image, 0.001


def quick_renderer():
    """Levels of a flat image whose value is the job's version / 10."""
    return _levels


def stalling_renderer():
    """Version 1 blocks after its first level until cancelled, then (uncooperatively)
    yields one more level; version 5 takes 1 s over its first level; other versions
    render at once. Version 3 raises; version 99 ends the process as a crash would."""
    def render(job, cancelled):
        if job.version == 3:
            raise ValueError("bad pose")
        if job.version == 5:
            mark = os.environ.get("TEXVOCAB_TEST_STARTED")
            if mark:  # tell the test this job has started (the process may be slow to)
                open(mark, "w").close()
            time.sleep(1.0)
        if job.version == 99:
            os._exit(7)
        yield from _levels(job, cancelled, (8,))
        if job.version == 1:
            t0 = time.perf_counter()
            while not cancelled() and time.perf_counter() - t0 < 30:
                time.sleep(0.005)
            yield 4, np.ones((4, 4, 3), np.float32), 0.001  # stale: must be dropped
            return
        yield from _levels(job, cancelled, (4, 2, 1))
    return render


def blas_reporting_renderer():
    """One level whose value is the number of BLAS threads numpy has in the process."""
    from texvocab.blas import blas_threads

    def render(job, cancelled):
        yield 1, np.full((2, 2, 3), float(blas_threads()), np.float32), 0.001
    return render


def failing_factory():
    raise RuntimeError("no model here")


def job(version: int) -> RenderJob:
    return RenderJob(version, np.zeros((24, 3)), np.zeros(3), camera=None)


def wait(predicate, timeout: float = 60.0) -> None:
    t0 = time.perf_counter()
    while not predicate():
        assert time.perf_counter() - t0 < timeout, "timed out"
        time.sleep(0.005)


def test_levels_arrive_from_another_process():
    woken = []
    worker = ProcessWorker(quick_renderer, threads=1, nice=3, on_frame=lambda: woken.append(1))
    try:
        assert worker.pid != os.getpid() and not worker.in_process
        worker.submit(job(1))
        assert worker.busy
        wait(lambda: not worker.busy)
        assert list(worker.delivered) == [(1, 8), (1, 4), (1, 2), (1, 1)]
        frame = worker.poll()
        assert frame.version == 1 and frame.level == 1 and frame.image.shape == (16, 16, 3)
        assert np.allclose(frame.image, 0.1) and worker.poll() is None
        assert len(woken) >= 4 and worker.errors == type(worker.errors)()
        assert os.getpriority(os.PRIO_PROCESS, worker.pid) == min(os.nice(0) + 3, 19)
        assert worker.alive and worker.cpu_seconds() > 0
    finally:
        assert worker.stop()
    assert not worker.alive


def test_the_render_process_keeps_numpy_blas_to_its_threads():
    """texvocab/blas.py: OpenBLAS would start a thread per core that spins after each call."""
    worker = ProcessWorker(blas_reporting_renderer, threads=1, nice=0, on_frame=lambda: None)
    try:
        worker.submit(job(1))
        wait(lambda: not worker.busy)
        frame = worker.poll()
        assert frame is not None and float(frame.image[0, 0, 0]) == 1.0
    finally:
        worker.stop()


def test_new_version_cancels_and_stale_levels_never_arrive():
    worker = ProcessWorker(stalling_renderer)
    try:
        worker.submit(job(1))
        wait(lambda: (1, 8) in worker.delivered)
        worker.submit(job(2))  # v1 is blocked in its render: this cancels it
        wait(lambda: not worker.busy)
        assert list(worker.delivered) == [(1, 8), (2, 8), (2, 4), (2, 2), (2, 1)]
        assert worker.latest.version == 2 and np.allclose(worker.latest.image, 0.2)
        worker.submit(job(2))  # a version already submitted is ignored
        assert not worker.busy
    finally:
        assert worker.stop()


def test_the_preview_in_progress_is_finished_and_shown_before_the_newest_job(
        tmp_path, monkeypatch):
    started = tmp_path / "started"
    monkeypatch.setenv("TEXVOCAB_TEST_STARTED", str(started))  # the child inherits it
    worker = ProcessWorker(stalling_renderer)
    try:
        worker.submit(job(4))  # the process is up and serving
        wait(lambda: not worker.busy)
        worker.submit(job(5))
        wait(started.exists)  # version 5 is in its first level (1 s)
        worker.submit(job(6))
        worker.submit(job(7))
        wait(lambda: not worker.busy)
        assert list(worker.delivered)[4:] == [(5, 8), (7, 8), (7, 4), (7, 2), (7, 1)]
    finally:
        assert worker.stop()


def test_a_failing_render_is_reported_and_the_process_keeps_serving():
    worker = ProcessWorker(stalling_renderer)
    try:
        worker.submit(job(3))
        wait(lambda: not worker.busy)
        assert len(worker.errors) == 1 and worker.errors[0].startswith("ValueError: bad pose (")
        assert "test_render_process.py" in worker.last_traceback
        worker.submit(job(4))
        wait(lambda: not worker.busy)
        assert worker.latest.version == 4 and worker.latest.level == 1
    finally:
        assert worker.stop()


def test_a_crashed_process_is_reported_not_waited_for():
    worker = ProcessWorker(stalling_renderer)
    try:
        worker.submit(job(99))
        wait(lambda: not worker.busy)
        wait(lambda: not worker.alive)
        assert any("exit code 7" in e for e in worker.errors), list(worker.errors)
        worker.submit(job(100))  # nothing left to render it: not busy forever
        assert not worker.busy
    finally:
        worker.stop()


@pytest.mark.parametrize("factory", [failing_factory])
def test_a_renderer_that_cannot_be_built_is_reported(factory):
    worker = ProcessWorker(factory)
    worker.submit(job(1))
    wait(lambda: not worker.busy)
    assert any(e.startswith("RuntimeError: no model here (") for e in worker.errors)
    worker.stop()
