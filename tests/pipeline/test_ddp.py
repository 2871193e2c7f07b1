"""Data-parallel training (texvocab train --ddp 2): two local CPU processes (gloo) give
the weights of one process that accumulates the same two shards of every step's batch,
and a time budget stops both at the same step. About 10 s each (two processes start
torch), measured in ./scripts/test."""

import numpy as np
import pytest
import torch

from texvocab.body import default_body
from texvocab.capture import open as open_capture
from texvocab.capture.motion import make_sequence
from texvocab.capture.synth import SynthSettings, synthesize
from texvocab.cli.main import main
from texvocab.io.checkpoint import load_checkpoint
from texvocab.pipeline.settings import Settings
from texvocab.pipeline.train import Trainer

pytestmark = pytest.mark.slow  # torch.distributed processes

SETS = [
    "texture_size=64",
    "num_keys=3",
    "k=2",
    "encoder=pyramid",
    "rays_per_batch=128",
    "coarse_samples=8",
    "fine_samples=4",
    "iterations=3",
    "checkpoint_every=3",
    "field.hidden=32",
    "field.sdf_layers=2",
    "field.color_layers=1",
    "field.pos_freqs=4",
    "perceptual=inception",
    "patch_size=14",
    "lr=2e-3",
]


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    poses, trans = make_sequence([("walk", 3), ("arm_raise", 2)], seed=5)
    return synthesize(
        tmp_path_factory.mktemp("ddp") / "cap",
        poses,
        trans,
        4,
        default_body(),
        SynthSettings(ring_views=6, raised_views=0, size=64, texture_size=128),
        progress=False,
    )


def accumulated(capture, out, world: int, steps: int) -> dict:
    """One process, every step: the `world` shards' losses back-propagated one after the
    other (each divided by `world`, DistributedDataParallel's mean), then one update."""
    tr = Trainer(open_capture(capture), Settings().with_overrides(SETS), out, progress=False)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # as each spawned process (2 cores / 2 processes)
    try:
        for _ in range(steps):
            state = tr.gen.get_state()
            tr.optim.zero_grad(set_to_none=True)
            for rank in range(world):
                tr.gen.set_state(state)
                tr.rank, tr.world = rank, world
                (tr.loss_terms()["loss"] / world).backward()
            tr.optim.step()
            tr.step += 1
    finally:
        torch.set_num_threads(threads)
    return tr.model.state_dict()


def test_two_processes_equal_one_process_accumulating_their_shards(capture, tmp_path):
    args = ["train", str(capture), "--out", str(tmp_path / "ddp"), "--ddp", "2"]
    assert main(args + sum((["--set", s] for s in SETS), [])) == 0
    ck = load_checkpoint(tmp_path / "ddp" / "checkpoint.pt")
    assert ck["step"] == 3
    ref = accumulated(capture, tmp_path / "ref", 2, 3)
    init = Trainer(
        open_capture(capture), Settings().with_overrides(SETS), tmp_path / "init", progress=False
    ).model.state_dict()
    moved = 0.0
    for name, value in ref.items():
        if value.dtype.is_floating_point:
            assert torch.allclose(ck["model"][name], value, rtol=1e-4, atol=1e-6), name
            moved = max(moved, float((value - init[name]).abs().max()))
    assert moved > 1e-3  # three steps changed the weights (the comparison is not vacuous)


def test_time_budget_stops_every_process_at_the_same_step(capture, tmp_path):
    sets = [s for s in SETS if not s.startswith(("iterations", "checkpoint_every"))]
    args = [
        "train",
        str(capture),
        "--out",
        str(tmp_path / "run"),
        "--ddp",
        "2",
        "--set",
        "iterations=100000",
        "--set",
        "max_minutes=0.05",
        "--set",
        "checkpoint_every=1000",
        "--set",
        "lr_decay=0.1",
    ]
    assert main(args + sum((["--set", s] for s in sets), [])) == 0
    ck = load_checkpoint(tmp_path / "run" / "checkpoint.pt")
    step = ck["step"]
    assert 1 <= step < 100000
    assert np.isfinite(step)
    # the learning rate decays over the budget, by the clock every process agreed on: the
    # last step's rate is the one its share of the budget gives
    lr, progress = ck["settings"]["train"]["lr"], ck["lr_schedule"]["progress"]
    assert ck["optimizer"]["param_groups"][0]["lr"] == pytest.approx(lr * 0.1**progress)
    assert 0 < progress < 1 if step >= 2 else progress == 0
