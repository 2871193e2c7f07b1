"""``texvocab synth`` and capture-related subcommands."""
from __future__ import annotations

import argparse
import time
from pathlib import Path


def add_synth_parser(sub, add_smpl) -> None:
    p = sub.add_parser(
        "synth", help="render a synthetic multi-view capture with ground truth",
        description="Render the default body (or --smpl) wearing procedural, pose-dependent "
                    "clothing from a ring of cameras, written as a ZJU-MoCap (default) or "
                    "THUman4.0 capture folder. With --poses, render any pose sequence "
                    "(novel poses); with --like, reuse another synthetic capture's cameras "
                    "and settings so the images are its ground truth.")
    p.add_argument("out", help="capture folder to create")
    p.add_argument("--layout", choices=("zju", "thuman"), default="zju")
    p.add_argument("--poses", metavar="FILE.npz", default=None,
                   help="poses (T, 24, 3) or (T, 72) [+ trans (T, 3)] instead of the default "
                        "procedural motion")
    p.add_argument("--like", metavar="CAPTURE", default=None,
                   help="copy cameras and settings from this synthetic capture")
    p.add_argument("--frames", type=int, default=None,
                   help="use only the first N frames of the motion")
    p.add_argument("--train-frames", type=int, default=None,
                   help="leading frames used for training (default: the motion's training "
                        "part, or all frames with --poses)")
    p.add_argument("--size", type=int, default=256, help="image side in pixels (default 256)")
    p.add_argument("--ring-views", type=int, default=8)
    p.add_argument("--raised-views", type=int, default=2)
    p.add_argument("--texture-size", type=int, default=1024)
    p.add_argument("--seed", type=int, default=0, help="motion seed (default 0)")
    p.add_argument("--overwrite", action="store_true", help="replace OUT if it exists")
    add_smpl(p)
    p.set_defaults(func=cmd_synth)


def cmd_synth(args: argparse.Namespace) -> int:
    from texvocab.body import load_body
    from texvocab.capture.motion import default_motion
    from texvocab.capture.synth import SynthSettings, load_pose_file, settings_of, synthesize

    body = load_body(args.smpl)
    cameras = None
    if args.like:
        from texvocab.capture import open as open_capture

        settings, cameras = settings_of(open_capture(args.like, body=body))
    else:
        settings = SynthSettings(ring_views=args.ring_views, raised_views=args.raised_views,
                                 size=args.size, texture_size=args.texture_size, seed=args.seed)
    if args.poses:
        poses, trans = load_pose_file(args.poses)
        num_train = len(poses)
    else:
        poses, trans, num_train = default_motion(args.seed)
    if args.frames:
        poses, trans = poses[: args.frames], trans[: args.frames]
    num_train = min(args.train_frames or num_train, len(poses))
    t0 = time.perf_counter()
    out = synthesize(args.out, poses, trans, num_train, body, settings, args.layout, cameras,
                     overwrite=args.overwrite, body_source=args.smpl or "default")
    n_views = len(cameras) if cameras else settings.ring_views + settings.raised_views
    print(f"wrote {len(poses)} frames x {n_views} views ({args.layout} layout, "
          f"{num_train} training frames) to {Path(out).resolve()} in "
          f"{time.perf_counter() - t0:.1f} s")
    return 0
