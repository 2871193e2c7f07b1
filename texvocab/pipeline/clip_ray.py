"""A clip's frames rendered in parallel as Ray tasks (``texvocab render --ray``): a local
Ray with N workers, or an existing cluster at ADDRESS. The model goes into Ray's object
store once and each worker (an actor) fetches it once, not once per frame; the driver
writes every frame it receives to the same cache as a serial render (resume works alike).

Ray is an optional extra (``pip install 'texvocab[scale]'``); every node of a cluster
needs texvocab installed in the same environment.
"""

from __future__ import annotations

from pathlib import Path

from tqdm import tqdm

from texvocab.errors import TexvocabError
from texvocab.io.images import save_png


def _ray():
    try:
        import ray
    except ImportError:
        raise TexvocabError("--ray needs Ray: pip install 'texvocab[scale]' (or pip install ray)") from None
    return ray


def render_frames_ray(
    model,
    march,
    scale: float,
    poses,
    trans,
    cameras,
    folder: Path,
    address: str | None = None,
    workers: int = 2,
    threads: int = 1,
    progress: bool = True,
) -> list[Path]:
    """Like :func:`texvocab.pipeline.clip.render_frames` with the renders on Ray actors.

    Args:
        address: an existing cluster ("auto", "ray://host:10001", ...); None starts a
            local Ray with ``workers`` CPUs (and shuts it down afterwards).
        workers: actors (one frame at a time each); threads: torch threads per actor.
    """
    ray = _ray()
    from ray.util import ActorPool

    from texvocab.pipeline.clip_worker import FrameWorker

    paths = [folder / f"frame_{i:05d}.png" for i in range(len(poses))]
    todo = [i for i, p in enumerate(paths) if not p.is_file()]
    started = not ray.is_initialized()
    if started:
        if address is None:
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False, configure_logging=False)
        else:
            ray.init(address=address, log_to_driver=False, configure_logging=False)
    try:
        model_ref = ray.put(model)  # once, into the object store
        actor = ray.remote(num_cpus=1)(FrameWorker)
        pool = ActorPool(
            [actor.remote(model_ref, march, scale, threads) for _ in range(max(1, min(workers, len(todo))))]
        )
        bar = tqdm(
            total=len(paths),
            initial=len(paths) - len(todo),
            unit="frame",
            desc=f"render (ray, {workers} workers)",
            disable=not progress,
        )
        jobs = [(i, poses[i], trans[i], cameras[i]) for i in todo]
        for i, image in pool.map_unordered(lambda a, job: a.render.remote(*job), jobs):
            save_png(paths[i], image)
            bar.update(1)
        bar.close()
    finally:
        if started:
            ray.shutdown()
    return paths
