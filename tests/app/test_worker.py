"""The viewer's progressive render worker (app/neural/worker.py), no GL: levels arrive coarse to
fine with timings, a newer version cancels stale work (stale levels never reach the UI),
and the thread stops cleanly, also in the middle of a render."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
import torch

from texvocab.capture.camera import Camera
from texvocab.render import MarchSettings, progressive_render
from texvocab.render.analytic import SphereField
from texvocab_viewer.neural.worker import ProgressiveWorker, RenderJob, model_renderer

SETTINGS = MarchSettings.from_flat(chunk_rays=64, coarse_samples=8, fine_samples=4)


def sphere_camera(size: int = 64) -> Camera:
    """Camera 1.2 m in front of the origin looking along +z (OpenCV)."""
    K = np.array([[size * 1.2, 0, size / 2], [0, size * 1.2, size / 2], [0, 0, 1]])
    return Camera(K=K, R=np.eye(3), t=np.array([0.0, 0.0, 1.2]), width=size, height=size)


def sphere_mesh():
    """A coarse icosphere-like mesh (V, 3), (F, 3) around the unit sphere field's surface."""
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=2, radius=0.3)
    return torch.tensor(m.vertices, dtype=torch.float32), torch.tensor(m.faces)


class CountingField:
    """SphereField that calls ``hook()`` (once armed) on its next evaluation."""

    def __init__(self):
        self.field = SphereField(radius=0.3)
        self.hook = None

    def __call__(self, points, dirs):
        if self.hook is not None:
            hook, self.hook = self.hook, None
            hook()
        return self.field(points, dirs)


def sphere_renderer(field, levels=(8, 4, 2, 1), after_level=None):
    """A LevelRenderer over the real progressive_render; ``after_level(job, level)`` runs
    after each level is yielded by the marcher (before the worker delivers it)."""
    v, f = sphere_mesh()

    def render(job, cancelled):
        for level, rgb, sec in progressive_render(
            field, job.camera, v, f, SETTINGS, levels, cancelled=cancelled
        ):
            if after_level is not None:
                after_level(job, level)
            yield level, rgb, sec

    return render


def job(version: int, size: int = 64) -> RenderJob:
    return RenderJob(version, np.zeros((24, 3)), np.zeros(3), sphere_camera(size))


def wait_idle(worker: ProgressiveWorker, timeout: float = 30.0) -> None:
    t0 = time.perf_counter()
    while worker.busy:
        assert time.perf_counter() - t0 < timeout, "worker still busy"
        time.sleep(0.01)


def test_levels_arrive_coarse_to_fine_with_timings():
    worker = ProgressiveWorker(sphere_renderer(CountingField()))
    seen = []
    worker.submit(job(1))
    t0 = time.perf_counter()
    while worker.busy or worker.latest is None or worker.latest.level != 1:
        frame = worker.poll()
        if frame is not None:
            seen.append(frame)
        assert time.perf_counter() - t0 < 30
        time.sleep(0.002)
    frame = worker.poll()
    if frame is not None:
        seen.append(frame)
    assert worker.stop()
    assert list(worker.delivered) == [(1, 8), (1, 4), (1, 2), (1, 1)]
    assert seen[-1].level == 1 and [f.level for f in seen] == sorted(f.level for f in seen)[::-1]
    assert [f.image.shape for f in seen][-1] == (64, 64, 3)
    assert all(f.seconds > 0 and f.version == 1 for f in seen)
    assert all(a.elapsed < b.elapsed for a, b in zip(seen, seen[1:]))
    centre, corner = seen[-1].image[32, 32], seen[-1].image[0, 0]
    assert centre.sum() > 0.3 and corner.sum() == 0  # the sphere over a black background
    assert worker.errors == type(worker.errors)()


def test_new_version_cancels_mid_level_and_stale_levels_never_arrive():
    field = CountingField()
    state = {}
    produced = []

    def after_level(j, level):
        produced.append((j.version, level))
        if j.version == 1 and level == 8:  # v1 is now marching level 4: change the pose
            field.hook = lambda: worker.submit(job(2))
            state["armed"] = True

    calls = []
    render = sphere_renderer(field, after_level=after_level)

    def spy(j, cancelled):
        calls.append(j.version)
        yield from render(j, cancelled)

    worker = ProgressiveWorker(spy)
    worker.submit(job(1))
    time.sleep(0.05)
    wait_idle(worker)
    assert worker.stop()
    assert state.get("armed")
    delivered = list(worker.delivered)
    assert delivered == [(1, 8), (2, 8), (2, 4), (2, 2), (2, 1)], delivered
    assert produced == delivered  # v1's level 4 was abandoned mid-march, not finished
    assert calls == [1, 2]
    assert worker.latest.version == 2 and worker.latest.level == 1


def test_levels_of_an_uncooperative_renderer_are_dropped_once_stale():
    """Even a renderer that ignores cancelled() cannot deliver a stale level."""
    release = threading.Event()

    def stubborn(j, cancelled):
        for level in (8, 4, 2, 1):
            if j.version == 1 and level == 4:
                release.wait(10)  # the UI submits version 2 while this level "renders"
            yield level, np.full((64 // level, 64 // level, 3), j.version / 10, np.float32), 0.01

    worker = ProgressiveWorker(stubborn, threads=None)
    worker.submit(job(1))
    t0 = time.perf_counter()
    while worker.latest is None:
        assert time.perf_counter() - t0 < 10
        time.sleep(0.005)
    worker.submit(job(2))
    release.set()
    time.sleep(0.05)
    wait_idle(worker)
    assert worker.stop()
    delivered = list(worker.delivered)
    assert delivered == [(1, 8), (2, 8), (2, 4), (2, 2), (2, 1)], delivered
    assert np.allclose(worker.latest.image, 0.2)


@pytest.mark.parametrize("finish_preview", [True, False])
def test_a_newer_job_lets_the_preview_in_progress_finish(finish_preview):
    """While a slider is dragged every UI frame submits a pose: each job's first level is
    finished and shown (labelled stale by the panel) before the newest job starts, so
    the drag shows poses as it goes. With ``finish_preview=False`` the newer job cancels
    the preview as it cancels finer levels."""
    started, release = threading.Event(), threading.Event()
    calls, seen_cancelled = [], []

    def render(j, cancelled):
        calls.append(j.version)
        if j.version == 1:
            started.set()
            release.wait(10)
            seen_cancelled.append(cancelled())
        for level in (8, 4, 2, 1):
            if cancelled():
                return
            yield level, np.full((64 // level, 64 // level, 3), j.version / 10, np.float32), 0.01

    worker = ProgressiveWorker(render, threads=None)
    first = RenderJob(1, np.zeros((24, 3)), np.zeros(3), sphere_camera(), finish_preview=finish_preview)
    worker.submit(first)
    assert started.wait(10)
    worker.submit(job(2))
    worker.submit(job(3))
    release.set()
    time.sleep(0.05)
    wait_idle(worker)
    assert worker.stop()
    assert calls == [1, 3]  # version 2 was superseded before it started
    assert seen_cancelled == [not finish_preview]
    preview = [(1, 8)] if finish_preview else []
    assert list(worker.delivered) == [*preview, (3, 8), (3, 4), (3, 2), (3, 1)]


def test_stop_joins_promptly_during_a_long_render():
    started = threading.Event()

    def slow(j, cancelled):
        started.set()
        while not cancelled():
            time.sleep(0.005)
        return
        yield  # a generator that never yields a level

    worker = ProgressiveWorker(slow, threads=None)
    worker.submit(job(1))
    assert started.wait(10) and worker.busy
    t0 = time.perf_counter()
    assert worker.stop(timeout=5)
    assert time.perf_counter() - t0 < 1.0 and not worker.alive
    assert list(worker.delivered) == []


def test_errors_are_reported_and_the_worker_keeps_serving():
    def flaky(j, cancelled):
        if j.version == 1:
            raise ValueError("boom")
        yield 1, np.ones((4, 4, 3), np.float32), 0.01

    worker = ProgressiveWorker(flaky, threads=None)
    worker.submit(job(1))
    time.sleep(0.05)
    wait_idle(worker)
    worker.submit(job(2))
    time.sleep(0.05)
    wait_idle(worker)
    assert worker.stop()
    assert len(worker.errors) == 1 and worker.errors[0].startswith("ValueError: boom (test_worker.py:")
    assert "raise ValueError" in worker.last_traceback
    assert list(worker.delivered) == [(2, 1)]


def test_same_version_is_not_rendered_twice():
    calls = []

    def once(j, cancelled):
        calls.append(j.version)
        yield 1, np.zeros((2, 2, 3), np.float32), 0.0

    worker = ProgressiveWorker(once, threads=None)
    for _ in range(3):
        worker.submit(job(7))
        time.sleep(0.02)
    wait_idle(worker)
    assert worker.stop()
    assert calls == [7]


def stub_model(make_field, calls=None, contexts=None):
    """A stand-in avatar with the attributes model_renderer uses: the sphere mesh as the
    posed body (with its surface index, on a lent layout as the real context builds it),
    ``make_field()`` as its field; counts context() calls in ``calls``, keeps each
    context in ``contexts``."""
    from texvocab.geometry.surface import SurfaceIndex

    v, f = sphere_mesh()

    class Ctx:
        vertices = v

        def __init__(self, like):
            self.like, self.index = like, SurfaceIndex(v.numpy(), f.numpy(), like=like)

    class Model:
        class body:
            faces = f

        class pose_feature:
            @staticmethod
            def warm_feature_maps():
                if calls is not None:
                    calls["warm"] = calls.get("warm", 0) + 1
                return 0

            @staticmethod
            def context(pose, trans, like=None):
                if calls is not None:
                    calls["context"] += 1
                ctx = Ctx(like)
                if contexts is not None:
                    contexts.append(ctx)
                return ctx

        @staticmethod
        def for_pose(ctx, precision="float32"):
            return make_field()

    return Model


@pytest.mark.parametrize("levels", [(4, 1)])
def test_model_renderer_uses_the_models_pose_context(levels):
    """model_renderer builds the per-pose context once and renders its field in levels."""
    calls = {"context": 0, "for_pose": 0}

    def field():
        calls["for_pose"] += 1
        return SphereField(radius=0.3)

    render = model_renderer(stub_model(field, calls), SETTINGS, levels)
    out = list(render(job(1, 32), lambda: False))
    assert [lv for lv, *_ in out] == list(levels)
    assert tuple(out[-1][1].shape) == (32, 32, 3)
    assert all(bool(owned.all()) for *_, owned in out)  # one shard: every pixel is its own
    assert calls == {"context": 1, "for_pose": 1, "warm": 1}  # the key maps: once, up front


def test_model_renderer_lends_the_last_layout_to_the_preview_then_splits_anew():
    """A job's surface index borrows the previous job's slot layout (a cheaper first
    level) and gets its own split before a finer level is rendered; a one-level job
    keeps the borrowed one, and a later shard (whose first level is not the preview)
    never borrows."""
    from dataclasses import replace

    contexts, borrowed_at = [], []
    sphere = SphereField(radius=0.3)

    def field(points, dirs):
        borrowed_at.append((contexts[-1].index.borrowed, points.shape[0]))
        return sphere(points, dirs)

    render = model_renderer(stub_model(lambda: field, contexts=contexts), SETTINGS, (4, 1))
    list(render(job(1, 32), lambda: False))
    assert contexts[0].like is None and not contexts[0].index.borrowed
    borrowed_at.clear()
    levels = render(job(2, 32), lambda: False)
    next(levels)  # the first level, on the lent layout
    assert contexts[1].like is contexts[0].index
    assert borrowed_at and all(b for b, _ in borrowed_at)
    borrowed_at.clear()
    list(levels)
    assert borrowed_at and not any(b for b, _ in borrowed_at)  # the full level: own split
    assert not contexts[1].index.borrowed
    list(render(replace(job(3, 32), levels=(4,)), lambda: False))
    assert contexts[2].like is contexts[1].index and contexts[2].index.borrowed
    list(render(replace(job(4, 32), shard=1, shards=2), lambda: False))
    assert contexts[3].like is None


def test_worker_thread_runs_at_the_requested_niceness():
    import os

    worker = ProgressiveWorker(lambda j, c: iter(()), threads=None, nice=7)
    t0 = time.perf_counter()
    while worker.native_id is None:
        assert time.perf_counter() - t0 < 5
        time.sleep(0.005)
    base = os.getpriority(os.PRIO_PROCESS, 0)
    assert os.getpriority(os.PRIO_PROCESS, worker.native_id) == min(base + 7, 19)
    assert worker.stop()


def test_a_job_renders_with_its_own_march_settings():
    """The viewer's preset combo sends the preset's MarchSettings with each job."""
    evals = []
    sphere = SphereField(radius=0.3)

    def counted(points, dirs):
        evals.append(points.shape[0])
        return sphere(points, dirs)

    render = model_renderer(stub_model(lambda: counted), SETTINGS, (1,))
    list(render(job(1, 32), lambda: False))
    own, evals[:] = sum(evals), []
    cheap = SETTINGS.replace(coarse_samples=max(2, SETTINGS.coarse_samples // 4), fine_samples=0)
    base = job(2, 32)
    list(render(RenderJob(2, base.pose, base.trans, base.camera, cheap), lambda: False))
    assert 0 < sum(evals) < 0.6 * own


def test_the_ui_can_wait_for_a_jobs_first_level():
    """ProgressiveWorker.wait_for: False once its timeout passes, True as soon as the
    job's first level is delivered, False at once when the worker is idle."""
    gate = threading.Event()

    def render(job, cancelled):
        gate.wait(10)
        yield 8, np.zeros((2, 2, 3), np.float32), 0.001

    worker = ProgressiveWorker(render)
    try:
        assert not worker.wait_for(1, 5.0)  # nothing submitted: no waiting
        worker.submit(job(1))
        t0 = time.perf_counter()
        assert not worker.wait_for(1, 0.1)
        assert 0.09 <= time.perf_counter() - t0 < 2
        threading.Timer(0.2, gate.set).start()
        assert worker.wait_for(1, 10.0) and worker.latest.version == 1
        assert time.perf_counter() - t0 >= 0.25
    finally:
        gate.set()
        assert worker.stop()
