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

from texvocab.io.stop_flag import Terminated, clear_stop, note_stop, recorded_stop

__all__ = ["Terminated", "interrupt_cause", "report_interrupt", "stop_signals"]


def _terminate(signum, frame) -> None:
    note_stop(Terminated)
    raise Terminated


def _interrupt(signum, frame) -> None:
    note_stop(KeyboardInterrupt)
    raise KeyboardInterrupt


@contextlib.contextmanager
def stop_signals() -> Iterator[None]:
    """For the block, SIGTERM raises :class:`Terminated` and SIGINT KeyboardInterrupt, each
    also noted for :func:`~texvocab.io.stop_flag.raise_if_stopped` (when this is the main
    thread and the signal has Python's default action: a host that set its own handler
    keeps it)."""
    main = threading.current_thread() is threading.main_thread()
    defaults = {signal.SIGTERM: signal.SIG_DFL, signal.SIGINT: signal.default_int_handler}
    handlers = {signal.SIGTERM: _terminate, signal.SIGINT: _interrupt}
    mine = [s for s in handlers if main and signal.getsignal(s) is defaults[s]]
    clear_stop()
    for s in mine:
        signal.signal(s, handlers[s])
    try:
        yield
    finally:
        for s in mine:
            signal.signal(s, defaults[s])
        clear_stop()


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
    SystemError raised from the KeyboardInterrupt. One that lands in ctypes' argument
    conversion comes out as a ``ctypes.ArgumentError`` naming it, with no chain at all:
    then the stop signal the handlers recorded is the cause."""
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return recorded_stop()
