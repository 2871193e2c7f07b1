"""A full disk met while writing (``ENOSPC``, or a quota: ``EDQUOT``), told in one line.

Every writer writes to a temporary file (or folder) beside its target and renames it into
place (:func:`texvocab.io.images.atomic_write_bytes`), removing it on any error, so a full
disk leaves the previous file as it was and no partial file behind. The callers that know
what was kept say so (``train``: the last checkpoint's step; ``prepare``: the texture maps
cached; ``synth``: that nothing was written); the command line says it for the rest.
"""

from __future__ import annotations

import errno
import os
from pathlib import Path

from texvocab.errors import TexvocabError

FULL_DISK_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT})


def disk_full_cause(exc: BaseException) -> OSError | None:
    """The OSError saying the disk (or the user's quota) is full that ``exc`` is, or was
    raised while handling (torch's writer turns it into a RuntimeError on its way out);
    None when there is none."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, OSError) and exc.errno in FULL_DISK_ERRNOS:
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


def is_disk_full(exc: BaseException) -> bool:
    """True when ``exc`` comes from a full disk (:func:`disk_full_cause`)."""
    return disk_full_cause(exc) is not None


def disk_full_reason(exc: OSError) -> str:
    """The reason in words: "no space left on device" or "disk quota exceeded"."""
    return os.strerror(exc.errno).lower()


def disk_full_error(path: str | Path, exc: BaseException, kept: str) -> TexvocabError:
    """The one-line error for a full disk (``exc``, or what it was raised from) while
    writing ``path``; ``kept`` says what is left intact (e.g. "the last checkpoint (step
    40) is intact")."""
    return TexvocabError(f"{path}: {disk_full_reason(disk_full_cause(exc) or exc)}; {kept}")
