"""A small real disk for full-disk tests: a tmpfs mounted for the test, shrunk on request
to what it holds plus a few bytes. Mounting needs root; this machine and its CI run the
suite as root. A user runs these tests under ``unshare -rm`` (root in a namespace of its
own); anywhere else they fail, saying so, rather than skip."""

import os
import subprocess
from contextlib import contextmanager
from pathlib import Path

import pytest

PAGE = 4096


class SmallDisk:
    """A tmpfs at ``root``; :meth:`leave` shrinks it so only ``free`` more bytes fit."""

    def __init__(self, root: Path):
        self.root = root

    def used(self) -> int:
        st = os.statvfs(self.root)
        return (st.f_blocks - st.f_bfree) * st.f_frsize

    def leave(self, free: int) -> None:
        size = self.used() + -(-free // PAGE) * PAGE
        assert size > 0, "a tmpfs of size 0 is unlimited: put a file on it first"
        subprocess.run(["mount", "-o", f"remount,size={size}", str(self.root)], check=True)


@contextmanager
def small_disk(tmp_path: Path):
    """``with small_disk(tmp_path) as disk:`` a 64 MiB tmpfs at tmp_path/disk for the block."""
    if os.geteuid() != 0:
        pytest.fail(
            "the full-disk tests mount a small tmpfs, which needs root: run them as root, or "
            "as a user under `unshare -rm python -m pytest ...` (root in its own namespace)"
        )
    root = tmp_path / "disk"
    root.mkdir()
    subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64m", "tmpfs", str(root)], check=True)
    try:
        yield SmallDisk(root)
    finally:
        subprocess.run(["umount", str(root)], check=True)
