"""The ``texvocab`` command line. Every subcommand has ``--help``; user errors print one
``error: ...`` line and exit with status 2."""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from texvocab.cli.capture import add_sheet_parser, add_synth_parser
from texvocab.cli.interrupts import interrupt_cause, report_interrupt, stop_signals
from texvocab.cli.method import add_method_parsers
from texvocab.cli.render import add_render_parser
from texvocab.cli.training import add_train_parsers
from texvocab.errors import TexvocabError
from texvocab.io.full_disk import disk_full_cause, disk_full_reason
from texvocab.io.outputs import check_output
from texvocab.pipeline.root_choice import ROOT_HELP, ROOTS

# The command line stands above the viewer (an import-linter contract: texvocab_viewer never
# imports texvocab.cli). The viewer's arguments module is light (no GL, no torch) and builds
# the `view` parser; the window, `shot` and the demo's viewer are imported inside the
# commands that run them, so `texvocab --help` loads neither imgui_bundle, moderngl nor torch.
from texvocab_viewer.arguments import add_other_capture, add_view_arguments


def _add_smpl(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--smpl",
        metavar="PATH",
        default=None,
        help="your SMPL model file or folder (see assets_spec/README.md); default: the embedded default body",
    )


def cmd_demo(args) -> int:
    # late: torch and GL; `texvocab --help` stays light
    from texvocab.cli.demo import demo_avatar, demo_capture, run_demo

    if not 16 <= args.size <= 4096:
        raise TexvocabError(f"--size {args.size}: expected a tile side of 16..4096 pixels")
    check_output(args.out, "folder")
    t0 = time.perf_counter()
    paths = run_demo(args.out, smpl=args.smpl, size=args.size)
    print(f"rendered the body in {len(paths) - 1} pose views in {time.perf_counter() - t0:.1f} s")
    print(f"  body poses sheet: {paths[0].resolve()}")
    print(f"  single views:     {paths[1].parent.resolve()}/")
    t0 = time.perf_counter()
    root, sheet = demo_capture(args.out, smpl=args.smpl, frames=args.frames)
    print(f"synthetic capture ready in {time.perf_counter() - t0:.1f} s")
    print(f"  capture (ZJU-MoCap layout): {root.resolve()}")
    print(f"  views x frames sheet:       {sheet.resolve()}")
    if args.train_minutes > 0:
        t0 = time.perf_counter()
        ckpt, report = demo_avatar(args.out, root, args.train_minutes, args.smpl)
        print(f"avatar trained and evaluated in {time.perf_counter() - t0:.1f} s")
        print(f"  checkpoint: {ckpt.resolve()}")
        print(f"  metrics:    {report.resolve()} (grids: {report.parent.resolve()}/grid_*.png)")
        print(report.read_text())
    source = ckpt if args.train_minutes > 0 else root
    if os.environ.get("DISPLAY") and not args.no_view:
        from texvocab_viewer.window import run_viewer  # late: imgui_bundle, moderngl, torch

        print(f"opening the viewer on {source} (close its window to finish)")
        return run_viewer(str(source), smpl=args.smpl, size=(1280, 800))
    from texvocab_viewer.export.shot import demo_shots  # late: moderngl and torch

    t0 = time.perf_counter()
    sheet = demo_shots(source, Path(args.out) / "viewer", smpl=args.smpl)
    print(f"no display (or --no-view): the viewer's shots written in {time.perf_counter() - t0:.1f} s")
    print(f"  viewer shots sheet: {sheet.resolve()}  (open the viewer: texvocab view {source})")
    return 0


def cmd_check_assets(args) -> int:
    from texvocab.cli.assets import check_path  # late: torch (texvocab.body)

    lines = check_path(args.path)
    print("\n".join(lines))
    return 1 if any(line.startswith("FAIL") or "no SMPL" in line for line in lines) else 0


def cmd_shot(args) -> int:
    check_output(args.out, "folder")
    from texvocab_viewer.export.shot import cmd_shot as run_shot  # late: moderngl and torch

    return run_shot(args)


def cmd_view(args) -> int:
    from texvocab_viewer.launch import run_from_args  # late: imgui_bundle, moderngl and torch

    return run_from_args(args)


SHOT_OVERLAYS = ("part_colors", "novelty", "wireframe", "skeleton")


def add_viewer_parsers(sub) -> None:
    """``view`` (the desktop viewer, texvocab_viewer) and ``shot`` (its headless screenshot)."""
    p = sub.add_parser(
        "view",
        help="the desktop viewer: pose, 3D view, vocabulary, neural render",
        description="Open the viewer window on a checkpoint (its avatar, "
        "vocabulary and capture), a capture folder (its vocabulary "
        "and texture maps) or, with no SOURCE, the body alone.",
    )
    add_view_arguments(p)
    p.set_defaults(func=cmd_view)

    p = sub.add_parser(
        "shot",
        help="headless screenshot of the viewer's 3D view (+ neural render)",
        description="Render the viewer's 3D view of a pose, and for a checkpoint "
        "the neural render from the same camera, offscreen (OSMesa, "
        "no display); write view3d.png, neural.png and shot.png "
        "(side by side) to --out and print their paths.",
    )
    p.add_argument(
        "source", nargs="?", default=None, help="checkpoint.pt or capture folder (default: the body alone)"
    )
    p.add_argument(
        "--pose",
        default="a_pose",
        help="a preset name (t_pose, a_pose, walk, squat, ...), a capture frame "
        "index N (or frame:N), or FILE.npz[:N] (default: a_pose)",
    )
    p.add_argument(
        "--root",
        choices=ROOTS,
        default="floor",
        help="where a FILE.npz pose stands in a capture's world (as texvocab render --root): " + ROOT_HELP,
    )
    p.add_argument(
        "--camera",
        default="0,0,3.2",
        help="a capture view index, or 'yaw,pitch,distance' of an orbit camera "
        "around the body (degrees, degrees, metres; default 0,0,3.2: the "
        "front)",
    )
    p.add_argument(
        "--size",
        default=None,
        metavar="WxH",
        help="image size (default: the capture view's size, else 640x400)",
    )
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument(
        "--overlay",
        nargs="+",
        default=[],
        choices=SHOT_OVERLAYS,
        metavar="NAME",
        help="any of: " + ", ".join(SHOT_OVERLAYS) + " (over the blended texture)",
    )
    p.add_argument(
        "--neural",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="also render the trained avatar (default: when SOURCE is a checkpoint)",
    )
    p.add_argument(
        "--capture",
        metavar="FOLDER",
        default=None,
        help="the capture folder a checkpoint was trained on, when it is not where the "
        "checkpoint records it (moved, or another machine)",
    )
    add_other_capture(p)
    _add_smpl(p)
    p.set_defaults(func=cmd_shot)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="texvocab", description="TexVocab: pose-driven avatars from multi-view video (CVPR 2024)."
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser(
        "demo",
        help="body poses, a synthetic capture, a short avatar run",
        description="Render the body (default, or --smpl) in six poses, front "
        "and side, offscreen; synthesise the default multi-view "
        "capture (reused if present), prepare its texture maps, "
        "train a short avatar and evaluate it; then open the "
        "viewer on it, or with no display write the viewer's "
        "screenshots; write PNGs and print where they are.",
    )
    p.add_argument("--out", default="out/demo", help="output folder (default: out/demo)")
    p.add_argument("--size", type=int, default=320, help="tile size in pixels (default: 320)")
    p.add_argument(
        "--frames", type=int, default=None, help="synthesise only the first N frames of the default capture"
    )
    p.add_argument(
        "--no-view",
        action="store_true",
        help="do not open the viewer at the end even with a display; write its "
        "screenshots instead (as without a display)",
    )
    p.add_argument(
        "--train-minutes",
        type=float,
        default=3.0,
        help="train the demo avatar this long (default 3; 0 skips training)",
    )
    _add_smpl(p)
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser(
        "check-assets",
        help="check SMPL files or a capture against assets_spec/",
        description="Say exactly what is wrong with an SMPL model file, UV file, "
        "a folder of them, or a capture folder (ZJU-MoCap / "
        "THUman4.0 / HumanNeRF), or that all is well.",
    )
    p.add_argument("path", help="a .pkl/.npz model, a smpl_uv.obj, a folder of them, or a capture folder")
    p.set_defaults(func=cmd_check_assets)

    add_synth_parser(sub, _add_smpl)
    add_sheet_parser(sub)

    add_method_parsers(sub, _add_smpl)
    add_render_parser(sub, _add_smpl)
    add_train_parsers(sub, _add_smpl)
    add_viewer_parsers(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run a command (:func:`run`: a user error is one ``error:`` line and status 2);
    Ctrl-C (SIGINT) ends it with one ``error: interrupted`` line and status 130, SIGTERM
    with ``error: terminated`` and 143 (:mod:`texvocab.cli.interrupts`)."""
    with stop_signals():
        try:
            return run(argv)
        except KeyboardInterrupt as exc:
            return report_interrupt(exc)
        except Exception as exc:  # an interrupt that an extension wrapped (a SystemError)
            cause = interrupt_cause(exc)
            if cause is None:
                raise
            return report_interrupt(cause)


def run(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from texvocab.blas import budget_blas_threads

    budget_blas_threads(1)  # torch's threads do the parallel work; OpenBLAS's would spin
    try:
        return args.func(args)
    except TexvocabError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (OSError, RuntimeError) as exc:  # a full disk no caller said more of (eval, render)
        full = disk_full_cause(exc)
        if full is None:
            raise
        where = f"{full.filename}: " if full.filename else ""
        print(f"error: {where}{disk_full_reason(full)} (texvocab {args.command})", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
