"""The run's per-step log, ``RUN/train_log.csv``: one row for each training step.

Columns: ``step``, ``seconds`` (training time since the run began, summed over resumed
sessions), ``loss``, ``psnr`` (of the step's batch of rays), ``eikonal``, ``perceptual``,
``beta`` (VolSDF's β, m), ``lr`` and ``evals`` (field evaluations). The file is rewritten
atomically with every checkpoint, so it always ends at the checkpoint's step; ``--resume``
keeps the rows up to the step it continues from and drops those a killed session made after
its last checkpoint, which the resumed run makes again.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

from texvocab.io.images import atomic_write_bytes

FILE_NAME = "train_log.csv"
COLUMNS = ("step", "seconds", "loss", "psnr", "eikonal", "perceptual", "beta", "lr", "evals")


def read_train_log(path: str | Path) -> list[dict]:
    """The rows of a run's ``train_log.csv`` (``path``: the file or its run folder), numbers
    parsed: step and evals int, the rest float."""
    path = Path(path)
    if path.is_dir():
        path = path / FILE_NAME
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    ints = {"step", "evals"}
    return [{k: (int(v) if k in ints else float(v)) for k, v in r.items()} for r in rows]


class TrainLog:
    """The rows of one run, held in memory and written with each checkpoint."""

    def __init__(self, run_dir: str | Path):
        self.path = Path(run_dir) / FILE_NAME
        self.rows: list[dict] = []

    def resume(self, step: int) -> None:
        """Continue a run at ``step``: its rows up to it (none if it kept no log)."""
        rows = read_train_log(self.path) if self.path.is_file() else []
        self.rows = [r for r in rows if r["step"] <= step]

    @property
    def seconds(self) -> float:
        """Training time the log holds so far (s)."""
        return self.rows[-1]["seconds"] if self.rows else 0.0

    def add(self, step: int, seconds: float, record: dict, lr: float) -> None:
        """One step's row: ``record`` a :meth:`Trainer.train_step` result."""
        row = {"step": step, "seconds": round(seconds, 3), "lr": lr}
        row.update({k: record[k] for k in COLUMNS if k in record})
        self.rows.append(row)

    def write(self) -> Path:
        """Write every row so far, atomically."""
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
        w.writeheader()
        for r in self.rows:
            w.writerow({k: (f"{r[k]:.6g}" if isinstance(r.get(k), float) else r.get(k, "")) for k in COLUMNS})
        data = buf.getvalue().encode()
        return atomic_write_bytes(self.path, lambda tmp: Path(tmp).write_bytes(data))
