"""Can an output be written? Every command asks before any long work: an output of the
wrong kind (a file where a folder is expected, or the reverse), or one whose folder (or
that folder's nearest existing parent) cannot be written, is one ``TexvocabError`` naming
the path and what was expected. Only ``stat`` and ``access`` are used: asking changes
nothing on disk.

Root passes permission bits, so ``access`` answers for root too where it matters: on a
read-only mount it says no (EROFS) to everyone."""

from __future__ import annotations

import os
from pathlib import Path

from texvocab.errors import TexvocabError


def nearest_existing(path: Path) -> Path:
    """``path`` itself, or its closest ancestor that exists (``/`` at the end)."""
    path = Path(os.path.abspath(path))
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def _why_not(folder: Path) -> str | None:
    """None when files can be created in the existing ``folder``; else why not."""
    if not folder.is_dir():
        return f"{folder} is a file, so no folder can be made there"
    if os.access(folder, os.W_OK | os.X_OK):
        return None
    try:
        readonly = bool(os.statvfs(folder).f_flag & os.ST_RDONLY)
    except OSError:
        readonly = False
    return f"{folder} is {'on a read-only file system' if readonly else 'not writable (permission denied)'}"


def folder_is_writable(folder: str | Path) -> bool:
    """Whether files can be created in ``folder``, made first where it does not exist yet
    (its nearest existing parent must be a writable folder)."""
    return _why_not(nearest_existing(Path(folder))) is None


def check_output(path: str | Path, kind: str, flag: str = "--out", whole: bool = False) -> Path:
    """Refuse an output that cannot be written, before any work; returns ``path``.

    ``kind``: ``"folder"`` (written inside: a run, a report, a PNG sequence) or
    ``"file"`` (written as a temporary file beside it, then renamed). ``whole``: a folder
    made elsewhere and renamed into place as a whole (``synth``), so its parent is what
    must be writable. ``flag`` names the option in the error line ("" for a positional).
    """
    path = Path(path)
    named = f"{flag} {path}" if flag else str(path)
    expected = "a folder" if kind == "folder" else "a file"
    if kind == "folder" and path.is_file():
        raise TexvocabError(f"{named}: is a file; expected {expected}")
    if kind == "file" and path.is_dir():
        raise TexvocabError(f"{named}: is a folder; expected {expected}")
    target = path.parent if kind == "file" or whole else path
    why = _why_not(nearest_existing(target))
    if why is not None:
        raise TexvocabError(f"{named}: cannot be written: {why}; expected {expected} texvocab can write")
    return path
