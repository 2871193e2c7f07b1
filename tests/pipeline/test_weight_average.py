"""The moving average of the weights (``train.weight_average``): the average follows its
formula, training's trajectory is the same with it, checkpoints hold the average for
evaluation and the raw weights for ``--resume``, and a resumed run ends as a straight one."""

import pytest
import torch
from train_cases import tiny_settings

from texvocab.capture import open as open_capture
from texvocab.errors import TexvocabError
from texvocab.pipeline.avatar import load_avatar
from texvocab.pipeline.settings import Settings
from texvocab.pipeline.train import Trainer
from texvocab.pipeline.weight_average import TRAINED_KEY, WeightAverage, trained_state


def test_the_average_follows_its_warmed_up_formula():
    model = torch.nn.Linear(2, 1)
    frozen = torch.nn.Parameter(torch.zeros(1), requires_grad=False)
    model.register_parameter("frozen", frozen)
    avg = WeightAverage(model, 0.5)
    assert avg.names == ["weight", "bias"]  # a frozen parameter is not averaged
    expected = model.weight.detach().clone()
    for n, value in enumerate([1.0, -2.0, 3.0, 0.5, 4.0, 4.0, 4.0, 4.0, 4.0, 4.0, 4.0, 4.0]):
        with torch.no_grad():
            model.weight.fill_(value)
        d = min(0.5, (1 + n) / (10 + n))
        expected = d * expected + (1 - d) * value
        avg.update()
        torch.testing.assert_close(avg.average[0], expected)
    assert avg.current_decay() == 0.5  # the warm-up is over: (1 + 12) / 22 > 0.5
    with pytest.raises(ValueError, match="decay"):
        WeightAverage(model, 1.0)


def test_the_setting_is_checked():
    with pytest.raises(TexvocabError, match="weight_average"):
        Settings().with_overrides(["train.weight_average=1"])
    assert Settings().with_overrides(["train.weight_average=0.995"]).train.weight_average == 0.995


def test_training_steps_the_raw_weights_and_checkpoints_hold_the_average(capture, tmp_path, one_thread):
    cap = open_capture(capture)
    plain = Trainer(cap, tiny_settings(iterations=8, checkpoint_every=8), tmp_path / "plain", progress=False)
    plain_logs = plain.run()
    s = tiny_settings(iterations=8, checkpoint_every=8, weight_average=0.5)
    averaged = Trainer(cap, s, tmp_path / "avg", progress=False)
    logs = averaged.run()
    assert [r["loss"] for r in logs] == [r["loss"] for r in plain_logs]  # same trajectory
    ck = torch.load(tmp_path / "avg" / "checkpoint.pt", weights_only=True)
    raw = plain.model.state_dict()
    for name in averaged.average.names:
        torch.testing.assert_close(ck[TRAINED_KEY]["parameters"][name], raw[name], rtol=0, atol=0)
    moved = [n for n in averaged.average.names if not torch.equal(ck["model"][n], raw[n])]
    assert len(moved) == len(averaged.average.names)  # every averaged weight differs from the raw
    trained = trained_state(ck)  # what a bench reads to score the raw weights
    for name in averaged.average.names:
        torch.testing.assert_close(trained[name], raw[name], rtol=0, atol=0)
    avatar = load_avatar(tmp_path / "avg" / "checkpoint.pt", cap, progress=False)
    loaded = avatar.model.state_dict()
    for name in averaged.average.names:  # evaluation and rendering read the average
        torch.testing.assert_close(loaded[name], ck["model"][name], rtol=0, atol=0)


def test_a_resumed_average_ends_as_a_straight_one(capture, tmp_path, one_thread):
    s = tiny_settings(iterations=6, checkpoint_every=3, weight_average=0.8)
    cap = open_capture(capture)
    straight = Trainer(cap, s, tmp_path / "a", progress=False)
    straight.run()
    first = Trainer(cap, s, tmp_path / "b", progress=False)
    first.run(until=3)
    resumed = Trainer(cap, s, tmp_path / "b", progress=False)
    assert resumed.resume() and resumed.step == 3 and resumed.average.updates == 3
    resumed.run()
    for a, b in zip(straight.average.average, resumed.average.average, strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=0)
    for a, b in zip(straight.average.params, resumed.average.params, strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=0)
