"""Data-parallel training on several processes (``texvocab train --ddp N``, or under
``torchrun``): torch.distributed with gloo on CPU (NCCL where CUDA exists).

Every process draws the whole batch of a step from the run's shared random stream and
renders its shard (:meth:`texvocab.pipeline.train.Trainer.loss_terms`); after the
backward pass the gradients are averaged across processes with one all-reduce, which is
DistributedDataParallel's rule. The all-reduce is explicit rather than through the
``DistributedDataParallel`` wrapper because the field is called through per-pose
closures, not through one module ``forward`` per step, which the wrapper's reducer
expects. Rank 0 holds the run folder's lock, shows progress and writes checkpoints; a
time budget stops every process at the same step.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import torch
import torch.distributed as dist


def backend() -> str:
    return "nccl" if torch.cuda.is_available() else "gloo"


def attach(trainer) -> None:
    """Make ``trainer`` one process of the current process group."""
    trainer.rank, trainer.world = dist.get_rank(), dist.get_world_size()
    params = [p for p in trainer.model.parameters() if p.requires_grad]

    def sync() -> None:
        # pose corrections: the step's frame's, the same on every process (one shared draw)
        drawn = (
            [] if trainer.refine is None else [p for p in trainer.refine.parameters() if p.grad is not None]
        )
        mine = params + drawn
        grads = [p.grad if p.grad is not None else torch.zeros_like(p) for p in mine]
        flat = torch.cat([g.reshape(-1) for g in grads])
        dist.all_reduce(flat, op=dist.ReduceOp.SUM)
        flat /= trainer.world
        start = 0
        for p, g in zip(mine, grads, strict=True):
            p.grad = flat[start : start + g.numel()].view_as(p).clone()
            start += g.numel()

    def agree(value: float) -> float:
        t = torch.tensor([float(value)], dtype=torch.float64)
        dist.all_reduce(t, op=dist.ReduceOp.MAX)
        return float(t.item())

    trainer.sync, trainer.agree = sync, agree
    trainer.progress = trainer.progress and trainer.rank == 0


def _worker(rank: int, world: int, init: str, job: dict) -> None:
    dist.init_process_group(backend(), init_method=init, rank=rank, world_size=world)
    try:
        torch.set_num_threads(job["threads"])
        run_process(job)
        dist.barrier()  # leave together: rank 0 may still be writing the checkpoint
    finally:
        dist.destroy_process_group()


def run_process(job: dict) -> None:
    """One process's training (the group is initialised): open the capture, build the
    trainer, resume if asked, train."""
    from texvocab.body import load_body
    from texvocab.capture import open as open_capture
    from texvocab.pipeline.train import Trainer

    cap = open_capture(job["capture"], body=load_body(job.get("smpl")), num_train=job.get("train_frames"))
    trainer = Trainer(cap, job["settings"], job["out"], progress=job.get("progress", True))
    attach(trainer)
    if job.get("resume"):
        trainer.resume(job.get("other_capture", False))
    trainer.run()


def spawn(world: int, job: dict) -> None:
    """Train on ``world`` local processes (threads split between them)."""
    import torch.multiprocessing as mp

    threads = max(1, torch.get_num_threads() // world)
    with tempfile.TemporaryDirectory() as tmp:
        init = Path(tmp, "rendezvous").as_uri()
        mp.spawn(_worker, args=(world, init, {**job, "threads": threads}), nprocs=world, join=True)


def under_torchrun() -> bool:
    """True in a process started by torchrun (its environment names a group of > 1)."""
    return int(os.environ.get("WORLD_SIZE", "1")) > 1 and "RANK" in os.environ
