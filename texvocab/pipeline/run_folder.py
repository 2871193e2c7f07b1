"""A training run folder is one writer's: a lock file holding the writer's pid stops a
second training on the same ``--out``; a lock whose process is gone is taken over; the
temp files a killed save leaves beside the checkpoint are removed by the next owner; and
a folder that already holds a trained checkpoint is only continued (``--resume``) or
replaced (``--overwrite``) on request, never silently.
"""

from __future__ import annotations

import os
from pathlib import Path

from texvocab.errors import TexvocabError
from texvocab.io.temp_files import pid_alive as _alive

LOCK_NAME = ".texvocab-train.lock"
CHECKPOINT_NAME = "checkpoint.pt"


def check_run_folder(out: Path, resume: bool, overwrite: bool) -> None:
    """Refuse an ``--out`` that is not a folder, or that holds a checkpoint when neither
    ``resume`` nor ``overwrite`` is asked for. Touches nothing."""
    if out.exists() and not out.is_dir():
        raise TexvocabError(
            f"--out {out}: is a file; expected a run folder (new or holding {CHECKPOINT_NAME})"
        )
    if resume and overwrite:
        raise TexvocabError("--resume and --overwrite exclude each other: continue the run or replace it")
    ckpt = out / CHECKPOINT_NAME
    if ckpt.exists() and not (resume or overwrite):
        raise TexvocabError(
            f"--out {out}: already holds a trained {CHECKPOINT_NAME}; pass "
            "--resume to continue it or --overwrite to replace it"
        )


class RunLock:
    """``with RunLock(out):`` holds ``out/.texvocab-train.lock`` (created exclusively, with
    this process's pid) for the block, and on entry removes stale checkpoint temp files.
    A lock left by a process that no longer runs is taken over."""

    def __init__(self, out: Path):
        self.out = Path(out)
        self.path = self.out / LOCK_NAME
        self.held = False

    def __enter__(self) -> RunLock:
        self.out.mkdir(parents=True, exist_ok=True)
        for _ in range(2):
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                pid = self._owner()
                if pid is not None and pid != os.getpid() and _alive(pid):
                    raise TexvocabError(
                        f"--out {self.out}: another training (pid {pid}) is "
                        f"writing this run folder; wait for it or choose "
                        "another --out"
                    ) from None
                self.path.unlink(missing_ok=True)  # stale: its process is gone
                continue
            with os.fdopen(fd, "w") as fh:
                fh.write(f"{os.getpid()}\n")
            self.held = True
            break
        if not self.held:
            raise TexvocabError(f"{self.path}: could not take the run folder's lock")
        for tmp in self.out.glob(f".{CHECKPOINT_NAME}.*"):  # a killed save's leftovers
            tmp.unlink(missing_ok=True)
        return self

    def _owner(self) -> int | None:
        try:
            return int(self.path.read_text().split()[0])
        except (OSError, ValueError, IndexError):
            return None

    def __exit__(self, *exc) -> None:
        if self.held and self._owner() == os.getpid():
            self.path.unlink(missing_ok=True)
        self.held = False
