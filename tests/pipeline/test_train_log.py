"""The run's per-step log (RUN/train_log.csv): a row for every step with the numbers the
step returned, ending at the checkpoint's step, and a resumed run's log the straight one's."""

import pytest
from train_cases import tiny_settings

from texvocab.capture import open as open_capture
from texvocab.pipeline.train import Trainer
from texvocab.pipeline.train_log import COLUMNS, read_train_log


def test_every_step_has_its_row(capture, tmp_path, one_thread):
    cap = open_capture(capture)
    trainer = Trainer(cap, tiny_settings(iterations=5, checkpoint_every=2), tmp_path / "run", progress=False)
    logs = trainer.run()
    rows = read_train_log(tmp_path / "run")
    assert [r["step"] for r in rows] == [1, 2, 3, 4, 5]
    assert list(rows[0]) == list(COLUMNS)
    for row, rec in zip(rows, logs, strict=True):
        assert row["psnr"] == pytest.approx(rec["psnr"], rel=1e-5)
        assert row["loss"] == pytest.approx(rec["loss"], rel=1e-5)
        assert row["beta"] == pytest.approx(rec["beta"], rel=1e-5) and row["evals"] == rec["evals"]
    seconds = [r["seconds"] for r in rows]
    assert seconds == sorted(seconds) and seconds[0] > 0


def test_a_resumed_run_keeps_the_rows_up_to_its_checkpoint(capture, tmp_path, one_thread):
    cap = open_capture(capture)
    s = tiny_settings(iterations=6, checkpoint_every=3)
    Trainer(cap, s, tmp_path / "a", progress=False).run()
    first = Trainer(cap, s, tmp_path / "b", progress=False)
    first.run(until=3)
    # a killed session: steps made after the last checkpoint, in memory only
    first.log_rows.add(4, 99.0, {"loss": 1.0, "psnr": 1.0}, 1e-3)
    assert [r["step"] for r in read_train_log(tmp_path / "b")] == [1, 2, 3]
    resumed = Trainer(cap, s, tmp_path / "b", progress=False)
    assert resumed.resume()
    resumed.run()
    straight, again = read_train_log(tmp_path / "a"), read_train_log(tmp_path / "b")
    assert [r["step"] for r in again] == [1, 2, 3, 4, 5, 6]
    assert [r["loss"] for r in again] == [r["loss"] for r in straight]  # the same run
    assert again[3]["seconds"] >= again[2]["seconds"]  # the time goes on across sessions
