"""Read-only folders that stop root too (the tests run as root, whom chmod does not
stop): a tmpfs mounted on a folder, filled, then remounted read-only. Every mount made
here is unmounted by :func:`unmount_all` (the fixtures' finalizers call it)."""

import shutil
import subprocess
from pathlib import Path

_mounted: list[Path] = []


def read_only_folder(folder: Path, fill=None) -> Path:
    """Mount a tmpfs on ``folder`` (made if missing), let ``fill(folder)`` write into it,
    and remount it read-only; returns ``folder``. Mounted once: later calls return it."""
    folder = Path(folder)
    if folder in _mounted:
        return folder
    folder.mkdir(parents=True, exist_ok=True)
    subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64m", "tmpfs", str(folder)], check=True)
    _mounted.append(folder)
    if fill is not None:
        fill(folder)
    subprocess.run(["mount", "-o", "remount,ro", str(folder)], check=True)
    return folder


def read_only_copy(src: Path, folder: Path) -> Path:
    """A read-only copy of the folder ``src`` (a capture) at ``folder``."""
    return read_only_folder(folder, lambda dst: shutil.copytree(src, dst, dirs_exist_ok=True))


def unmount_all() -> None:
    while _mounted:
        subprocess.run(["umount", "-l", str(_mounted.pop())], check=False)
