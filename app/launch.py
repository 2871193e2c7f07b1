"""The viewer's command line: ``python -m texvocab_viewer [SOURCE] [--size WxH] ...`` and
``texvocab view`` (the same arguments, :func:`texvocab_viewer.arguments.add_view_arguments`)
check them and open the window (:func:`texvocab_viewer.window.run_viewer`). The hidden
``--script NAME --report FILE.json [--screenshot FILE.png]`` drive it for tests and
benchmarks (:mod:`texvocab_viewer.testing`)."""

from __future__ import annotations

import argparse
import atexit
import os
import sys

from texvocab.errors import TexvocabError
from texvocab_viewer.arguments import PREVIEW_WAIT_MAX_MS, WINDOW_MIN, add_view_arguments, parse_size
from texvocab_viewer.testing.registry import Script
from texvocab_viewer.window import run_viewer

PROG = "python -m texvocab_viewer"


def run_from_args(args: argparse.Namespace) -> int:
    """Run the viewer from :func:`texvocab_viewer.arguments.add_view_arguments`' namespace.
    Once the window has closed, the process ends at once with its exit code
    (:func:`exit_now`)."""
    if args.neural_processes < 1:
        raise TexvocabError(f"--neural-processes {args.neural_processes}: expected at least 1")
    if not 0 <= args.neural_preview_wait <= PREVIEW_WAIT_MAX_MS:
        raise TexvocabError(
            f"--neural-preview-wait {args.neural_preview_wait:g}: expected "
            f"0..{PREVIEW_WAIT_MAX_MS:g} milliseconds"
        )
    size = parse_size(args.size, WINDOW_MIN)
    script = None if args.script is None else Script(args.script, args.report, args.screenshot)
    rc = run_viewer(
        args.source,
        args.smpl,
        size,
        script,
        args.neural_resolution,
        args.neural_threads,
        args.poses,
        args.neural_nice,
        args.capture,
        args.neural_worker,
        args.neural_processes,
        args.neural_preview_wait,
        other_capture=args.other_capture,
    )
    exit_now(rc)
    return rc  # not reached


def exit_now(rc: int) -> None:
    """End the process with ``rc`` after its exit handlers, without the interpreter's
    teardown of its modules: with torch, GL and the ImGui backend loaded that takes about
    a second on a loaded machine, after the window has already closed. Everything the
    viewer writes is written (exports are finished or removed by then)."""
    atexit._run_exitfuncs()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(rc)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog=PROG, description="the texvocab viewer: pose, 3D view, vocabulary, neural render"
    )
    add_view_arguments(p)
    args = p.parse_args(argv)
    try:
        return run_from_args(args)
    except TexvocabError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
