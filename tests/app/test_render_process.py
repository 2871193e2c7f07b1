"""The viewer's render process (app/neural/render_process.py): the thread worker's protocol
across a process boundary. Levels arrive coarse to fine from another process, a newer
version cancels the job in progress and stale levels never arrive, a failing render is
reported and the process keeps serving, a crashed process is reported, and stop ends it.
The renderers are module-level factories: the child imports this module to build them."""

from __future__ import annotations

import os
import time

import numpy as np
import pytest

from texvocab_viewer.neural.render_process import ProcessWorker
from texvocab_viewer.neural.worker import RenderJob


def _levels(job, cancelled, levels=(8, 4, 2, 1)):
    for level in levels:
        if cancelled():
            return
        image = np.full((max(1, 16 // level), max(1, 16 // level), 3), job.version / 10, np.float32)
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


def shard_renderer():
    """The levels of a 21x13 view as shard ``job.shard`` of ``job.shards`` renders them
    (texvocab.render.level_owners): its pixels hold 1 + the shard, the others 0; shard 1
    is slower, so the shards' levels arrive interleaved."""
    from texvocab.render import level_owners

    def render(job, cancelled):
        marks = os.environ.get("TEXVOCAB_TEST_SHARDS")  # when each shard started, and
        if marks:  # when the first shard's first level was done (after 0.3 s)
            with open(os.path.join(marks, f"start-{job.version}-{job.shard}"), "w") as f:
                f.write(repr(time.time()))
        h, w, levels = job.camera.height, job.camera.width, (8, 4, 2, 1)
        mine = np.zeros((h, w), bool)
        image = np.zeros((h, w, 3), np.float32)
        for level, owner in zip(levels, level_owners(h, w, levels, job.shards)):
            if cancelled():
                return
            time.sleep(0.02 * job.shard)
            if marks and job.shard == 0 and level == 8:
                time.sleep(0.3)
                with open(os.path.join(marks, f"preview-{job.version}"), "w") as f:
                    f.write(repr(time.time()))
            now = (owner == job.shard).numpy()
            mine |= now
            image[now] = 1 + job.shard
            yield level, image[::level, ::level].copy(), 0.001, mine[::level, ::level].copy()
            if job.preview_only:
                return

    return render


class Size:  # what a sharded job reads of its camera
    height, width = 21, 13


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


def test_two_processes_split_a_view_and_their_levels_are_merged():
    from texvocab.render import level_owners

    worker = ProcessWorker(shard_renderer, threads=1, nice=2, processes=2)
    try:
        assert len(set(worker.pids)) == 2 and os.getpid() not in worker.pids
        for version in (1, 2):
            worker.submit(RenderJob(version, np.zeros((24, 3)), np.zeros(3), camera=Size()))
            wait(lambda: not worker.busy)
        levels = (8, 4, 2, 1)
        assert [lv for v, lv in worker.delivered if v == 2] == list(levels)  # each once
        frame = worker.latest
        assert frame.version == 2 and frame.level == 1 and frame.image.shape == (21, 13, 3)
        # every pixel from the shard that owns it, at any level
        expected = np.zeros((21, 13), np.float32)
        for owner in level_owners(21, 13, levels, 2):
            expected[owner.numpy() >= 0] = 1 + owner.numpy()[owner.numpy() >= 0]
        np.testing.assert_array_equal(frame.image[..., 0], expected)
        assert {1.0, 2.0} <= set(np.unique(frame.image).tolist())
        assert worker.cpu_seconds() > 0
        # the second shard runs nicer, so the first (the preview's) wins a shared core
        assert (
            os.getpriority(os.PRIO_PROCESS, worker.pids[1])
            == os.getpriority(os.PRIO_PROCESS, worker.pids[0]) + 5
        )
    finally:
        assert worker.stop()
    assert not worker.alive


def test_later_shards_wait_for_the_preview_and_skip_jobs_superseded_by_then(tmp_path, monkeypatch):
    """While a slider is dragged each pose is cancelled after its preview: the second
    shard starts a job only once the first has sent that preview, so it neither slows
    the preview nor works on poses already left. A playback job (no preview) starts on
    both at once; a preview-only job (a dragged pose's) goes to the first alone, and is
    done when it is."""
    monkeypatch.setenv("TEXVOCAB_TEST_SHARDS", str(tmp_path))  # the children inherit it

    def mark(name):
        return float((tmp_path / name).read_text())

    worker = ProcessWorker(shard_renderer, processes=2)
    try:

        def submit(version, **kw):
            worker.submit(RenderJob(version, np.zeros((24, 3)), np.zeros(3), camera=Size(), **kw))

        submit(1)
        wait(lambda: not worker.busy)
        assert mark("start-1-1") >= mark("preview-1")
        submit(2)
        wait(lambda: (tmp_path / "start-2-0").exists())
        submit(3)  # version 2's preview is still 0.3 s away
        wait(lambda: not worker.busy)
        assert (tmp_path / "preview-2").exists() and not (tmp_path / "start-2-1").exists()
        assert [lv for v, lv in worker.delivered if v == 3] == [8, 4, 2, 1]
        assert mark("start-3-1") >= mark("preview-3")
        submit(4, finish_preview=False)  # as a playback render: no preview to wait for
        wait(lambda: not worker.busy)
        assert mark("start-4-1") < mark("preview-4")
        submit(5, preview_only=True)
        wait(lambda: not worker.busy)
        assert [lv for v, lv in worker.delivered if v == 5] == [8]
        assert (tmp_path / "start-5-0").exists() and not (tmp_path / "start-5-1").exists()
    finally:
        assert worker.stop()


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


def test_the_preview_in_progress_is_finished_and_shown_before_the_newest_job(tmp_path, monkeypatch):
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


def test_the_ui_can_wait_for_a_jobs_first_level():
    """ProcessWorker.wait_for (the viewer's pose frame waiting for the preview,
    NeuralView.late_poll): False once its timeout passes, True as soon as a level of the
    job is delivered, and False at once when the job ends without one (an error)."""
    worker = ProcessWorker(stalling_renderer)
    try:
        worker.submit(job(2))  # renders at once: the process is ready after it
        wait(lambda: not worker.busy)
        worker.submit(job(3))  # raises before any level
        t0 = time.perf_counter()
        assert not worker.wait_for(3, 30.0)
        assert time.perf_counter() - t0 < 15 and not worker.busy
        worker.submit(job(5))  # 1 s before its first level
        t0 = time.perf_counter()
        assert not worker.wait_for(5, 0.1)
        assert 0.09 <= time.perf_counter() - t0 < 0.9
        assert worker.wait_for(5, 30.0)
        assert worker.latest.version == 5 and time.perf_counter() - t0 >= 0.5
        assert worker.wait_for(4, 0.0)  # an older job's: the newer level counts
    finally:
        assert worker.stop()


def test_ctrl_c_in_the_terminal_leaves_the_render_process_to_the_viewer():
    """SIGINT reaches the whole process group; the child ignores it (no traceback of its
    own) and keeps serving until the viewer stops it."""
    import signal

    worker = ProcessWorker(quick_renderer, threads=1)
    try:
        worker.submit(job(1))
        wait(lambda: not worker.busy)
        os.kill(worker.pid, signal.SIGINT)
        time.sleep(0.3)
        assert worker.alive
        worker.submit(job(2))
        wait(lambda: (2, 1) in worker.delivered)
    finally:
        assert worker.stop()
