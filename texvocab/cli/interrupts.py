"""Ctrl-C and ``kill``: a command stopped by SIGINT (Ctrl-C) or SIGTERM ends with one
line on stderr, ``error: interrupted`` (exit status 130) or ``error: terminated`` (143),
and no traceback. Both arrive as :class:`KeyboardInterrupt` wherever the command is, so
every writer's ``except BaseException``/``finally`` removes its temporary files first."""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Iterator


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the main thread is, like Ctrl-C's KeyboardInterrupt."""


def _terminate(signum, frame) -> None:
    raise Terminated


@contextlib.contextmanager
def stop_signals() -> Iterator[None]:
    """For the block, SIGTERM raises :class:`Terminated` (when this is the main thread and
    SIGTERM has its default action: a host that set its own handler keeps it)."""
    mine = threading.current_thread() is threading.main_thread()
    mine = mine and signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    if mine:
        signal.signal(signal.SIGTERM, _terminate)
    try:
        yield
    finally:
        if mine:
            signal.signal(signal.SIGTERM, signal.SIG_DFL)


def report_interrupt(exc: KeyboardInterrupt) -> int:
    """Close any progress bar (so the line starts on a line of its own), print the one
    line, and return the exit status: 143 for SIGTERM, 130 for Ctrl-C."""
    bars = getattr(sys.modules.get("tqdm"), "tqdm", None)
    for bar in list(getattr(bars, "_instances", ())):
        with contextlib.suppress(Exception):
            bar.close()
    terminated = isinstance(exc, Terminated)
    print(f"error: {'terminated' if terminated else 'interrupted'}", file=sys.stderr)
    return 143 if terminated else 130


def interrupt_cause(exc: BaseException) -> KeyboardInterrupt | None:
    """The KeyboardInterrupt behind ``exc``, if one is in its chain of causes: a signal
    that lands inside a compiled extension (numba's dispatcher, for one) comes out as a
    SystemError raised from the KeyboardInterrupt."""
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None
