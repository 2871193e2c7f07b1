"""Where texvocab keeps what it derives from a capture (the texture maps): inside the
capture, ``CAPTURE/texvocab_cache/``, when that can be written; else, for a capture on a
read-only mount (or a folder this user cannot write), in the user's cache folder,
``$XDG_CACHE_HOME`` (default ``~/.cache``) ``/texvocab/captures/NAME-DIGEST/``, where NAME
is the capture folder's name and DIGEST a short digest of its absolute path. One
function, :func:`capture_cache`, decides it for every command that writes or reads the
cache; the first time it picks the user's folder for a capture, one warning line says so.
"""

from __future__ import annotations

import hashlib
import logging
import os
from pathlib import Path

from texvocab.io.outputs import folder_is_writable

log = logging.getLogger("texvocab")

CACHE_NAME = "texvocab_cache"
_told: set[str] = set()  # captures whose moved cache this process has announced


def user_cache_home() -> Path:
    """``$XDG_CACHE_HOME`` when set to an absolute path (the XDG rule), else ``~/.cache``."""
    xdg = os.environ.get("XDG_CACHE_HOME", "")
    return Path(xdg) if os.path.isabs(xdg) else Path.home() / ".cache"


def user_capture_cache(root: str | Path) -> Path:
    """The user-cache folder of capture ``root``: NAME-DIGEST (module docstring)."""
    absolute = Path(root).resolve()
    digest = hashlib.sha1(str(absolute).encode()).hexdigest()[:10]
    return user_cache_home() / "texvocab" / "captures" / f"{absolute.name or 'capture'}-{digest}"


def capture_cache(root: str | Path) -> Path:
    """The cache folder of capture ``root``: ``root/texvocab_cache`` when it can be written
    there, else :func:`user_capture_cache` (announced once per process)."""
    own = Path(root) / CACHE_NAME
    if folder_is_writable(own):
        return own
    moved = user_capture_cache(root)
    key = str(Path(root).resolve())
    if key not in _told:
        _told.add(key)
        log.warning("capture %s is read-only: texture maps go to %s", root, moved)
    return moved
