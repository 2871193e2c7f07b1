"""``texvocab prepare`` (texture maps, Sec. 3.2) and ``texvocab vocab`` (Sec. 3.3–3.4);
``train`` and ``eval`` are in :mod:`texvocab.cli.training`.

build_parser imports this module, so the commands import what they run (torch) inside
their functions: ``texvocab --help`` stays light."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from texvocab.errors import TexvocabError


def add_method_parsers(sub, add_smpl) -> None:
    p = sub.add_parser(
        "prepare",
        help="build the texture maps U_t of a capture (cached)",
        description="Back-project every training view onto the posed body and "
        "average in UV space (Eq. 2); one texture map and coverage "
        "map per training frame, cached under "
        "CAPTURE/texvocab_cache/ (for a read-only capture: the user's cache "
        "folder, ~/.cache/texvocab/captures/). Resumable: cached frames are kept.",
    )
    p.add_argument("capture", help="capture folder")
    p.add_argument("--texture-size", type=int, default=256, help="texels per side (default 256)")
    p.add_argument(
        "--train-frames",
        type=int,
        default=None,
        help="leading training frames (default: the capture's split)",
    )
    p.add_argument(
        "--eval-views",
        type=int,
        nargs="*",
        default=None,
        metavar="V",
        help="held-out views, never back-projected (default: the settings' "
        "eval_views, 1 5); the maps use every other view",
    )
    add_smpl(p)
    p.set_defaults(func=cmd_prepare)

    p = sub.add_parser(
        "vocab",
        help="print the vocabulary keys a pose selects",
        description="Build the body-part vocabulary from a capture's training "
        "poses and print, per part, the K selected keys, their "
        "source frames, weights and the distance to the nearest key.",
    )
    p.add_argument("capture", help="capture folder")
    p.add_argument(
        "--pose",
        required=True,
        help="a preset name (t_pose, walk, squat, ...), 'frame:N' for a frame of "
        "the capture, or FILE.npz[:N] with 'poses'",
    )
    p.add_argument("--strategy", choices=("part", "joint", "global"), default="part")
    p.add_argument("--keys", type=int, default=20, help="M keys per part (default 20)")
    p.add_argument("-k", type=int, default=3, help="K nearest keys (default 3)")
    p.add_argument(
        "--weighting",
        choices=("paper", "inverse"),
        default="paper",
        help="paper: w = J_p - d (Eq. 6); inverse: 1/d",
    )
    p.add_argument(
        "--min-distance",
        type=float,
        default=0.0,
        help="adaptive M: stop adding keys to a part once every training pose of "
        "it is within this Eq. 4 distance of a key (default 0: always M)",
    )
    p.add_argument(
        "--pose-condition",
        choices=("root-relative", "global"),
        default="root-relative",
        help="the pose keys and queries read: root-relative (default: joint 0's "
        "rotation, which way the body faces, removed) or global (as "
        "checkpoints trained before it)",
    )
    p.add_argument("--train-frames", type=int, default=None)
    add_smpl(p)
    p.set_defaults(func=cmd_vocab)


def open_from_args(args):
    """The capture ``args.capture`` names, posed by ``args.smpl``, split by ``--train-frames``."""
    # late: torch; `texvocab --help` stays light (module docstring)
    from texvocab.body import load_body
    from texvocab.capture import open as open_capture

    return open_capture(
        args.capture, body=load_body(args.smpl), num_train=getattr(args, "train_frames", None)
    )


def cmd_prepare(args: argparse.Namespace) -> int:
    # late: torch (module docstring)
    from texvocab.method.texmap import (
        cache_dir,
        coverage_note,
        load_texture_map,
        prepare_texture_maps,
        seen_texel_share,
    )
    from texvocab.pipeline.model import texmap_settings
    from texvocab.pipeline.settings import DataSettings, Settings

    cap = open_from_args(args)
    if cap.num_train == 0:
        raise TexvocabError(f"{args.capture}: no training frames (--train-frames)")
    views = {} if args.eval_views is None else {"eval_views": tuple(args.eval_views)}
    settings = texmap_settings(cap, Settings(data=DataSettings(texture_size=args.texture_size, **views)))
    t0 = time.perf_counter()
    paths = prepare_texture_maps(cap, settings)
    print(
        f"{len(paths)} texture maps ({settings.size}² texels, views "
        f"{','.join(map(str, settings.views))}) in {cache_dir(cap, settings)} "
        f"({time.perf_counter() - t0:.1f} s)"
    )
    coverage = np.stack([load_texture_map(p)[1] for p in paths])
    line, warning = coverage_note(seen_texel_share(coverage, cap.body), cap.frame_ids)
    print(line)
    if warning is not None:
        print(f"warning: {warning}", file=sys.stderr)
    return 0


def _index(text: str, what: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise TexvocabError(f"{what}: {text!r} is not a frame number") from None


def parse_pose(spec: str, capture) -> np.ndarray:
    """A (24, 3) pose from a preset name, 'frame:N' or 'FILE.npz[:N]'."""
    # late: torch (module docstring)
    from texvocab.body.poses import PRESETS, preset
    from texvocab.capture.synth import load_pose_file

    if spec in PRESETS:
        return preset(spec)[0]
    if spec.startswith("frame:"):
        n = _index(spec.split(":", 1)[1], f"--pose {spec}")
        if not 0 <= n < capture.num_frames:
            raise TexvocabError(f"--pose {spec}: the capture has frames 0..{capture.num_frames - 1}")
        return capture.poses[n]
    path, _, idx = spec.partition(":") if spec.count(":") == 1 and not Path(spec).exists() else (spec, "", "")
    if Path(path).suffix == ".npz":
        poses, _ = load_pose_file(path)
        n = _index(idx or "0", f"--pose {spec}")
        if not 0 <= n < len(poses):
            raise TexvocabError(f"--pose {spec}: {path} has {len(poses)} poses")
        return poses[n]
    raise TexvocabError(
        f"--pose {spec!r}: expected a preset ({', '.join(sorted(PRESETS))}), 'frame:N' or FILE.npz[:N]"
    )


def cmd_vocab(args: argparse.Namespace) -> int:
    from texvocab.method.vocab import Vocabulary  # late: torch (module docstring)

    for name, value, low in (
        ("--keys", args.keys, 1),
        ("-k", args.k, 1),
        ("--min-distance", args.min_distance, 0),
    ):
        if not value >= low:
            raise TexvocabError(f"{name} {value}: expected at least {low}")
    cap = open_from_args(args)
    if cap.num_train == 0:
        raise TexvocabError(f"{args.capture}: no training frames to build a vocabulary from")
    keys = min(args.keys, cap.num_train)  # the keys are training frames
    if keys < args.keys:
        print(f"--keys {args.keys}: the capture has {cap.num_train} training frames; using {keys} keys")
    if args.k > keys:  # K nearest of the M keys (Eq. 4)
        raise TexvocabError(
            f"-k {args.k}: expected at most the number of keys ({keys}): K of the M keys per part"
        )
    pose = parse_pose(args.pose, cap)
    vocab = Vocabulary.build(
        cap.poses[: cap.num_train],
        args.strategy,
        keys,
        args.k,
        args.weighting,
        args.min_distance,
        args.pose_condition,
    )
    print(f"pose: {args.pose}   training frames: {cap.num_train}")
    print(vocab.format_query(pose))
    return 0
