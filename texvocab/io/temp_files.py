"""texvocab's temporary files: named for their writer, swept when their writer is gone.

Every file texvocab writes in place (checkpoints, texture maps, frames, reports, videos)
and every capture ``synth`` makes is first written under a temporary name in the same
folder, ``.NAME.tmp-PID-HOST-RANDOM[SUFFIX]``: PID is the writer's process id, HOST a
short digest of its host name. A writer that stops normally, on an error or on Ctrl-C
removes its own; one killed outright (SIGKILL, a power cut) cannot. The next texvocab
process that writes into that folder removes the temporary files whose writer ran on
this host and no longer runs (:func:`sweep_stale`). Nothing else is touched: only names
of exactly this pattern, never a file texvocab did not name so.
"""

from __future__ import annotations

import hashlib
import os
import re
import secrets
import shutil
import socket
import tempfile
from pathlib import Path

TEMP_NAME = re.compile(r"^\.(?P<name>.+)\.tmp-(?P<pid>\d+)-(?P<host>[0-9a-f]{6})-[a-z0-9_]+(\.[^.]+)?$")
_swept: set[str] = set()  # folders this process has swept already


def host_tag() -> str:
    """Six hex digits naming this host in temporary names."""
    return hashlib.sha1(socket.gethostname().encode()).hexdigest()[:6]


def temp_prefix(name: str) -> str:
    """The start of a temporary name for the file or folder ``name`` (module docstring)."""
    return f".{name}.tmp-{os.getpid()}-{host_tag()}-"


def temp_file(path: Path) -> Path:
    """Create an empty temporary file beside ``path`` (same suffix: writers that pick the
    format from it still do) and return its path."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=temp_prefix(path.name), suffix=path.suffix)
    os.close(fd)
    return Path(tmp)


def temp_dir(path: Path) -> Path:
    """Create an empty temporary folder beside ``path`` and return its path."""
    return Path(tempfile.mkdtemp(dir=path.parent, prefix=temp_prefix(path.name)))


def temp_name(path: Path) -> Path:
    """A fresh temporary name beside ``path`` for a tool that creates the file itself."""
    return path.with_name(f"{temp_prefix(path.name)}{secrets.token_hex(4)}{path.suffix}")


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` runs on this host (someone else's counts)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # someone else's live process
    except OverflowError:
        return False
    return True


def sweep_stale(folder: Path, force: bool = False) -> list[Path]:
    """Remove the temporary files and folders in ``folder`` whose writer ran on this host
    and is gone; returns what was removed. Once per folder per process unless ``force``."""
    key = os.path.abspath(folder)
    if key in _swept and not force:
        return []
    _swept.add(key)
    removed = []
    here, me = host_tag(), os.getpid()
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return []
    for entry in entries:
        m = TEMP_NAME.match(entry.name)
        if m is None or m["host"] != here or int(m["pid"]) == me or pid_alive(int(m["pid"])):
            continue
        try:
            if entry.is_dir(follow_symlinks=False):
                shutil.rmtree(entry.path)
            else:
                os.unlink(entry.path)
        except OSError:
            continue
        removed.append(Path(entry.path))
    return removed
