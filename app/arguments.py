"""Command-line arguments of the viewer, shared by ``texvocab view``/``shot`` and
``python -m texvocab_viewer``: one size parser, one ``view`` argument set, and the
defaults the window and its panels start from. Light: no GL, no torch (the ``texvocab``
parser imports it to build its ``--help``), and the bottom of the package's layers."""

from __future__ import annotations

import argparse
import os

from texvocab.errors import TexvocabError

#: niceness added to the neural render thread: the UI, llvmpipe and the X server come
#: first. bench/viewer_ui.py on a busy 2-core box: UI frame while rendering / idle 1.24-1.53
#: at 0, 1.07-1.08 at 10; but other busy processes then also win over the render.
NEURAL_NICE = 10

#: where the neural render runs: a process of its own (app/neural/render_process.py; the
#: default) or a thread of the viewer's (app/neural/worker.py), which shares the interpreter
NEURAL_WORKERS = ("process", "thread")

#: render processes that split each view (app/neural/render_process.py), one per core up to 2:
#: the UI idles while a level renders, so the second core is free then
NEURAL_PROCESSES = min(2, os.cpu_count() or 1)

#: milliseconds from a pose change (after a pause) that its frame waits, once ImGui drew
#: it and before the swap (llvmpipe rasterises it meanwhile), for the neural render's
#: preview, which is then drawn over the panel's image: both reach the screen in one
#: frame instead of the preview a frame later (texvocab_viewer.viewer.Viewer.before_swap). In the
#: 1280x800 window under llvmpipe on 2 cores the preview of a 256-px render arrived
#: 17-34 ms after the change while the frame waited; with 30 ms about 1 render in 12
#: missed the wait (then the preview shows a frame later, as without it), with 40 none
#: of 24 (bench/viewer_ui.py)
NEURAL_PREVIEW_WAIT_MS = 40.0
#: the longest wait accepted: a frame held longer would feel like a stall
PREVIEW_WAIT_MAX_MS = 200.0
#: while a slider is dragged, the frame that changes the pose waits for that pose's
#: preview until this many milliseconds after the frame began, less what recent frames
#: took after their wait (the swap, input): the frame stays within 33 ms (30 frames per
#: second); unless --neural-preview-wait is 0 (texvocab_viewer.viewer.Viewer.before_swap)
DRAG_FRAME_MS = 28.0

#: smallest window the docked panels fit in; smallest offscreen image
WINDOW_MIN = (320, 240)
IMAGE_MIN = (16, 16)


def parse_size(spec: str, minimum: tuple[int, int] = IMAGE_MIN) -> tuple[int, int]:
    """'WxH' -> (W, H), each within [minimum, 8192]; TexvocabError naming --size otherwise."""
    w, sep, h = spec.lower().partition("x")
    try:
        size = (int(w), int(h))
    except ValueError:
        size = None
    if not sep or size is None or not all(lo <= v <= 8192 for v, lo in zip(size, minimum)):
        raise TexvocabError(
            f"--size {spec!r}: expected WIDTHxHEIGHT, e.g. 1280x800 "
            f"({minimum[0]}..8192 x {minimum[1]}..8192 pixels)"
        )
    return size


def add_other_capture(p: argparse.ArgumentParser) -> None:
    """``--other-capture`` of ``view`` and ``shot``: accept a capture other than the one
    the checkpoint was trained on."""
    p.add_argument(
        "--other-capture",
        action="store_true",
        help="show the checkpoint on a capture it was not trained on (other frames, views "
        "or calibration; refused without it), with one warning line",
    )


def add_view_arguments(p: argparse.ArgumentParser) -> None:
    """The viewer's arguments (``texvocab view`` and ``python -m texvocab_viewer``)."""
    p.add_argument(
        "source", nargs="?", default=None, help="checkpoint.pt or capture folder (default: the body alone)"
    )
    p.add_argument(
        "--size", default="1280x800", metavar="WxH", help="window size (default 1280x800, at least 320x240)"
    )
    p.add_argument(
        "--poses",
        default=None,
        metavar="FILE.npz",
        help="a pose sequence .npz for the Pose panel's timeline: SMPL (T, 24, 3) "
        "or (T, 72) [+ trans], AMASS SMPL-H (T, 156) or SMPL-X (T, 165)",
    )
    p.add_argument(
        "--smpl",
        metavar="PATH",
        default=None,
        help="your SMPL model file or folder (see assets_spec/README.md); default: the embedded default body",
    )
    p.add_argument(
        "--capture",
        metavar="FOLDER",
        default=None,
        help="the capture folder a checkpoint was trained on, when it is not where the "
        "checkpoint records it (moved, or another machine)",
    )
    add_other_capture(p)
    p.add_argument("--script", default=None, help=argparse.SUPPRESS)
    p.add_argument("--report", default=None, help=argparse.SUPPRESS)
    p.add_argument("--screenshot", default=None, help=argparse.SUPPRESS)
    p.add_argument("--neural-resolution", type=int, default=None, help=argparse.SUPPRESS)
    p.add_argument("--neural-threads", type=int, default=1, help=argparse.SUPPRESS)
    p.add_argument(
        "--neural-nice",
        type=int,
        default=NEURAL_NICE,
        metavar="N",
        help=f"niceness added to the neural render (default {NEURAL_NICE}: the UI "
        "first; 0 shows about 2.5x more previews while a slider is dragged, "
        "at up to 12%% longer UI frames; bench/viewer_ui.py)",
    )
    p.add_argument(
        "--neural-processes",
        type=int,
        default=NEURAL_PROCESSES,
        metavar="N",
        help=f"render processes that split each neural render (default "
        f"{NEURAL_PROCESSES}: one per core, at most 2); each holds a copy of "
        "the model. With --neural-worker thread: 1",
    )
    p.add_argument(
        "--neural-preview-wait",
        type=float,
        default=NEURAL_PREVIEW_WAIT_MS,
        metavar="MS",
        help=f"after a pause, the frame that changes the pose waits up to MS "
        f"milliseconds from the change for the neural preview, so the 3D view "
        f"and the preview show together (default {NEURAL_PREVIEW_WAIT_MS:g}; "
        "0: never wait, not even while a slider is dragged, when a frame "
        f"waits up to {DRAG_FRAME_MS:g} ms from its start, less its swap; bench/viewer_ui.py)",
    )
    p.add_argument(
        "--neural-worker",
        choices=NEURAL_WORKERS,
        default=NEURAL_WORKERS[0],
        help="where the neural render runs: processes of their own (default; the "
        "UI's Python does not slow them) or a thread of the viewer's",
    )
