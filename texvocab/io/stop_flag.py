"""A stop signal that a library swallowed still stops the command before it commits.

Ctrl-C and SIGTERM arrive as :class:`KeyboardInterrupt` wherever the main thread is
(:mod:`texvocab.cli.interrupts`). Some libraries catch every exception around a step and
carry on (trimesh's vertex normals fall back to a slower path on any error, the interrupt
included), so the command would finish and put its output in place as if never stopped.
The signal handlers therefore also note the signal here, and every writer calls
:func:`raise_if_stopped` just before it renames its output into place.
"""

from __future__ import annotations


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the main thread is, like Ctrl-C's KeyboardInterrupt."""


_stopped: list[type[KeyboardInterrupt]] = []  # the interrupt each stop signal raised


def note_stop(kind: type[KeyboardInterrupt]) -> None:
    """Record that a stop signal arrived (called by the signal handlers)."""
    _stopped.append(kind)


def clear_stop() -> None:
    """Forget recorded signals (a command's start and end)."""
    _stopped.clear()


def raise_if_stopped() -> None:
    """Raise the interrupt of the first stop signal recorded, if any: called before a
    writer renames its output into place."""
    stop = recorded_stop()
    if stop is not None:
        raise stop


def recorded_stop() -> KeyboardInterrupt | None:
    """The interrupt of the first stop signal recorded, or None."""
    return _stopped[0]() if _stopped else None
