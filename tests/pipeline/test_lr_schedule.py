"""The learning rate over a run (``train.lr_decay``): exponential decay over the run's
steps or its time budget, whichever ends it first, every parameter group scaled alike,
and a resumed run continuing from the progress its checkpoint stored."""

import numpy as np
import pytest
import torch
from train_cases import tiny_settings

from texvocab.capture import open as open_capture
from texvocab.pipeline.lr_schedule import LearningRateSchedule
from texvocab.pipeline.train import Trainer


def _optim(lrs=(1e-3, 5e-3)) -> torch.optim.Adam:
    groups = [{"params": [torch.nn.Parameter(torch.zeros(2))], "lr": lr} for lr in lrs]
    return torch.optim.Adam(groups)


def test_decay_over_steps_scales_every_group():
    opt = _optim()
    sched = LearningRateSchedule(opt, 0.1)
    sched.begin(0, 100, None)
    first = sched.update(0, 0.0)
    assert first == pytest.approx(1e-3)
    mid = sched.update(50, 123.0)  # no budget: the clock does not count
    assert mid == pytest.approx(1e-3 * 0.1**0.5)
    assert opt.param_groups[1]["lr"] == pytest.approx(5e-3 * 0.1**0.5)
    assert sched.update(100, 0.0) == pytest.approx(1e-4)


def test_a_time_budget_that_ends_the_run_first_sets_the_pace():
    sched = LearningRateSchedule(_optim(), 0.1)
    sched.begin(0, 10_000, 60.0)
    assert sched.update(10, 30.0) == pytest.approx(1e-3 * 0.1**0.5)  # half the budget
    assert sched.update(5000, 29.0) == pytest.approx(1e-3 * 0.1**0.5)  # half the steps
    assert sched.update(5001, 59.9) < 1.01e-4 * 10**0.01
    # progress never runs backwards, nor past the end
    assert sched.update(5002, 0.0) == pytest.approx(sched.update(5003, 0.0))
    assert sched.update(9999, 600.0) == pytest.approx(1e-4)


def test_a_resumed_schedule_spreads_the_rest_over_what_remains():
    sched = LearningRateSchedule(_optim(), 0.01)
    sched.begin(0, 100, None)
    sched.update(49, 0.0)
    state = sched.state(50)  # a checkpoint after 50 steps
    assert state["progress"] == pytest.approx(0.5)
    again = LearningRateSchedule(_optim(), 0.01)
    again.load(state)
    again.begin(50, 100, 10.0)  # resumed with a time budget of its own
    assert again.update(50, 0.0) == pytest.approx(1e-3 * 0.01**0.5)
    assert again.update(51, 5.0) == pytest.approx(1e-3 * 0.01**0.75)
    old = LearningRateSchedule(_optim(), 0.1)
    old.load(None)  # a checkpoint written before the schedule: from the start
    assert old.progress == 0.0


def test_constant_rate_when_decay_is_one():
    sched = LearningRateSchedule(_optim(), 1.0)
    sched.begin(0, 10, 1.0)
    assert {sched.update(s, s * 0.5) for s in range(10)} == {1e-3}


def test_training_logs_the_decayed_rate_and_stores_the_progress(capture, tmp_path):
    s = tiny_settings(iterations=12, checkpoint_every=6, lr_decay=0.1)
    trainer = Trainer(open_capture(capture), s, tmp_path / "run", progress=False)
    logs = trainer.run()
    lrs = np.array([r["lr"] for r in logs])
    assert lrs[0] == pytest.approx(2e-3)
    assert np.all(np.diff(lrs) < 0)
    assert lrs[-1] == pytest.approx(2e-3 * 0.1 ** (11 / 12))
    assert trainer.optim.param_groups[0]["lr"] == pytest.approx(lrs[-1])
    ck = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=True)
    assert ck["lr_schedule"]["progress"] == pytest.approx(1.0)  # where step 13 would start
