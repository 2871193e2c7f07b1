"""``texvocab prepare`` (texture maps, Sec. 3.2) and ``texvocab vocab`` (Sec. 3.3–3.4)."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from texvocab.errors import TexvocabError


def add_method_parsers(sub, add_smpl) -> None:
    p = sub.add_parser("prepare", help="build the texture maps U_t of a capture (cached)",
                       description="Back-project every training view onto the posed body and "
                                   "average in UV space (Eq. 1); one texture map and coverage "
                                   "map per training frame, cached under "
                                   "CAPTURE/texvocab_cache/. Resumable: cached frames are kept.")
    p.add_argument("capture", help="capture folder")
    p.add_argument("--texture-size", type=int, default=256, help="texels per side (default 256)")
    p.add_argument("--train-frames", type=int, default=None,
                   help="leading training frames (default: the capture's split)")
    add_smpl(p)
    p.set_defaults(func=cmd_prepare)

    p = sub.add_parser("vocab", help="print the vocabulary keys a pose selects",
                       description="Build the body-part vocabulary from a capture's training "
                                   "poses and print, per part, the K selected keys, their "
                                   "source frames, weights and the distance to the nearest key.")
    p.add_argument("capture", help="capture folder")
    p.add_argument("--pose", required=True,
                   help="a preset name (t_pose, walk, squat, ...), 'frame:N' for a frame of "
                        "the capture, or FILE.npz[:N] with 'poses'")
    p.add_argument("--strategy", choices=("part", "joint", "global"), default="part")
    p.add_argument("--keys", type=int, default=20, help="M keys per part (default 20)")
    p.add_argument("-k", type=int, default=3, help="K nearest keys (default 3)")
    p.add_argument("--weighting", choices=("paper", "inverse"), default="paper",
                   help="paper: w = J_p - d (Eq. 4); inverse: 1/d")
    p.add_argument("--train-frames", type=int, default=None)
    add_smpl(p)
    p.set_defaults(func=cmd_vocab)


def _open(args):
    from texvocab.body import load_body
    from texvocab.capture import open as open_capture

    return open_capture(args.capture, body=load_body(args.smpl), num_train=args.train_frames)


def cmd_prepare(args: argparse.Namespace) -> int:
    from texvocab.texmap import TexmapSettings, cache_dir, prepare_texture_maps

    cap = _open(args)
    if cap.num_train == 0:
        raise TexvocabError(f"{args.capture}: no training frames (--train-frames)")
    settings = TexmapSettings(size=args.texture_size)
    t0 = time.perf_counter()
    paths = prepare_texture_maps(cap, settings)
    print(f"{len(paths)} texture maps ({settings.size}² texels) in {cache_dir(cap, settings)} "
          f"({time.perf_counter() - t0:.1f} s)")
    return 0


def parse_pose(spec: str, capture) -> np.ndarray:
    """A (24, 3) pose from a preset name, 'frame:N' or 'FILE.npz[:N]'."""
    from texvocab.body.poses import PRESETS, preset
    from texvocab.capture.synth import load_pose_file

    if spec in PRESETS:
        return preset(spec)[0]
    if spec.startswith("frame:"):
        n = int(spec.split(":", 1)[1])
        if not 0 <= n < capture.num_frames:
            raise TexvocabError(f"--pose {spec}: the capture has frames 0..{capture.num_frames - 1}")
        return capture.poses[n]
    path, _, idx = spec.partition(":") if spec.count(":") == 1 and not Path(spec).exists() \
        else (spec, "", "")
    if Path(path).suffix == ".npz":
        poses, _ = load_pose_file(path)
        n = int(idx or 0)
        if not 0 <= n < len(poses):
            raise TexvocabError(f"--pose {spec}: {path} has {len(poses)} poses")
        return poses[n]
    raise TexvocabError(f"--pose {spec!r}: expected a preset ({', '.join(sorted(PRESETS))}), "
                        "'frame:N' or FILE.npz[:N]")


def cmd_vocab(args: argparse.Namespace) -> int:
    from texvocab.vocab import Vocabulary

    cap = _open(args)
    if cap.num_train == 0:
        raise TexvocabError(f"{args.capture}: no training frames to build a vocabulary from")
    pose = parse_pose(args.pose, cap)
    vocab = Vocabulary.build(cap.poses[: cap.num_train], args.strategy, args.keys, args.k,
                             args.weighting)
    print(f"pose: {args.pose}   training frames: {cap.num_train}")
    print(vocab.format_query(pose))
    return 0
