"""``texvocab synth`` and capture-related subcommands.

build_parser imports this module, so the commands import what they run (torch, PIL)
inside their functions: ``texvocab --help`` stays light."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from texvocab.errors import TexvocabError
from texvocab.io.outputs import check_output, folder_is_writable


def add_synth_parser(sub, add_smpl) -> None:
    p = sub.add_parser(
        "synth",
        help="render a synthetic multi-view capture with ground truth",
        description="Render the default body (or --smpl) wearing procedural, pose-dependent "
        "clothing from a ring of cameras, written as a ZJU-MoCap (default) or "
        "THUman4.0 capture folder. With --poses, render any pose sequence "
        "(novel poses); with --like, reuse another synthetic capture's cameras "
        "and settings so the images are its ground truth.",
    )
    p.add_argument("out", help="capture folder to create")
    p.add_argument("--layout", choices=("zju", "thuman"), default="zju")
    p.add_argument(
        "--motion",
        choices=("default", "compositional"),
        default="default",
        help="default: walk, arm raises, squat, twist, random poses (72 training "
        "frames), then 30 novel frames of the same kinds; compositional: "
        "five whole-body combinations of part motions train, and 30 novel "
        "frames recombine those part poses in ways never seen together "
        "(the body-part vocabulary's case; README, 'Captures')",
    )
    p.add_argument(
        "--poses",
        metavar="FILE.npz",
        default=None,
        help="poses instead of the default procedural motion: SMPL (T, 24, 3) or "
        "(T, 72) [+ trans (T, 3)], AMASS SMPL-H (T, 156) or SMPL-X (T, 165) "
        "(resampled to 30 fps, turned Z-up -> +Y up)",
    )
    p.add_argument(
        "--like",
        metavar="CAPTURE",
        default=None,
        help="copy cameras and settings from this synthetic capture",
    )
    p.add_argument("--frames", type=int, default=None, help="use only the first N frames of the motion")
    p.add_argument(
        "--train-frames",
        type=int,
        default=None,
        help="leading frames used for training (default: the motion's training "
        "part; with --poses: all frames, or none with --like, i.e. a "
        "novel-pose ground-truth set)",
    )
    p.add_argument("--size", type=int, default=256, help="image side in pixels (default 256)")
    p.add_argument("--ring-views", type=int, default=8)
    p.add_argument("--raised-views", type=int, default=2)
    p.add_argument("--texture-size", type=int, default=1024)
    p.add_argument("--seed", type=int, default=0, help="motion seed (default 0)")
    p.add_argument(
        "--garment",
        default="painted",
        help="what the body wears: painted (default: the body mesh with painted folds), "
        "hoodie, wide-trousers, loose (cloth geometry off the body, lit fold ridges; "
        "docs/data.md, 'Garments')",
    )
    p.add_argument(
        "--cloth-slide",
        type=float,
        default=0.0,
        metavar="M",
        help="the garment's pattern slides over the body with each part's bend, up to M "
        "metres at the cuffs and hems (default 0: the cloth stays put; docs/data.md, "
        "'Garments')",
    )
    p.add_argument(
        "--fit-noise-deg",
        type=float,
        default=0.0,
        help="record SMPL fits with this RMS rotation error per joint, degrees (default 0: exact)",
    )
    p.add_argument(
        "--fit-noise-trans",
        type=float,
        default=0.0,
        help="record root translations with this RMS error, metres (default 0)",
    )
    p.add_argument("--exposure-sd", type=float, default=0.0, help="per-camera exposure offset sd, stops")
    p.add_argument(
        "--white-balance-sd", type=float, default=0.0, help="per-camera, per-channel gain sd, stops"
    )
    p.add_argument("--sensor-noise", type=float, default=0.0, help="per-pixel Gaussian noise sd (0..1 units)")
    p.add_argument("--overwrite", action="store_true", help="replace OUT if it exists")
    add_smpl(p)
    p.set_defaults(func=cmd_synth)


#: Largest image and garment texture sides ``synth`` renders (pixels per side), and most
#: cameras of each kind.
SYNTH_LIMITS = {"size": 4096, "texture_size": 4096, "ring_views": 64, "raised_views": 64}


def cmd_synth(args: argparse.Namespace) -> int:
    # late: torch; `texvocab --help` stays light (module docstring)
    from texvocab.body import load_body
    from texvocab.capture.garment_sets import garment_spec
    from texvocab.capture.motion import default_motion
    from texvocab.capture.synth import SynthSettings, load_pose_file, settings_of, synthesize

    for name in ("frames", "ring_views", "size", "texture_size"):
        value = getattr(args, name, None)
        if value is not None and not 1 <= value <= SYNTH_LIMITS.get(name, value):
            top = f" and at most {SYNTH_LIMITS[name]}" if name in SYNTH_LIMITS else ""
            raise TexvocabError(f"--{name.replace('_', '-')} {value}: expected at least 1{top}")
    if args.raised_views > SYNTH_LIMITS["raised_views"]:
        raise TexvocabError(
            f"--raised-views {args.raised_views}: expected at most {SYNTH_LIMITS['raised_views']}"
        )
    if args.raised_views < 0 or (args.train_frames is not None and args.train_frames < 0):
        raise TexvocabError("--raised-views and --train-frames must not be negative")
    realism = {
        k: getattr(args, k, 0.0)
        for k in (
            "fit_noise_deg",
            "fit_noise_trans",
            "exposure_sd",
            "white_balance_sd",
            "sensor_noise",
            "cloth_slide",
        )
    }
    limits = {"sensor_noise": 1.0, "cloth_slide": 0.2}
    bad = [k for k, v in realism.items() if not 0.0 <= v <= limits.get(k, 90.0)]
    if bad:
        flag = "--" + bad[0].replace("_", "-")
        raise TexvocabError(f"{flag} {realism[bad[0]]}: expected a value >= 0 (and a sensible size)")
    garment = getattr(args, "garment", "painted")
    garment_spec(garment)  # AssetError (a TexvocabError) for an unknown name
    check_output(args.out, "folder", flag="", whole=True)  # made beside it, renamed into place
    body = load_body(args.smpl)
    cameras = None
    if args.like:
        from texvocab.capture import open as open_capture  # late: as above

        settings, cameras = settings_of(open_capture(args.like, body=body))
    else:
        settings = SynthSettings(
            ring_views=args.ring_views,
            raised_views=args.raised_views,
            size=args.size,
            texture_size=args.texture_size,
            seed=args.seed,
            garment=garment,
            **realism,
        )
    if args.poses:
        poses, trans = load_pose_file(args.poses)
        num_train = 0 if args.like else len(poses)
    elif args.motion == "compositional":
        from texvocab.capture.compositional import compositional_motion  # late: as above

        poses, trans, num_train = compositional_motion(args.seed)
    else:
        poses, trans, num_train = default_motion(args.seed)
    if len(poses) == 0:
        raise TexvocabError(f"--poses {args.poses}: holds 0 frames; expected at least 1")
    if args.frames is not None:
        poses, trans = poses[: args.frames], trans[: args.frames]
    if args.train_frames is not None:
        num_train = args.train_frames
    num_train = min(num_train, len(poses))
    t0 = time.perf_counter()
    out = synthesize(
        args.out,
        poses,
        trans,
        num_train,
        body,
        settings,
        args.layout,
        cameras,
        overwrite=args.overwrite,
        body_source=args.smpl or "default",
    )
    n_views = len(cameras) if cameras else settings.ring_views + settings.raised_views
    print(
        f"wrote {len(poses)} frames x {n_views} views ({args.layout} layout, "
        f"{num_train} training frames) to {Path(out).resolve()} in "
        f"{time.perf_counter() - t0:.1f} s"
    )
    return 0


def add_sheet_parser(sub) -> None:
    p = sub.add_parser(
        "contact-sheet",
        help="write a views x frames PNG of a capture",
        description="Tile a capture's images (rows: views, columns: frames) into one PNG to look at.",
    )
    p.add_argument("capture", help="capture folder (ZJU-MoCap, THUman4.0 or HumanNeRF layout)")
    p.add_argument(
        "--out",
        default=None,
        help="PNG path (default: CAPTURE/contact_sheet.png for a synthetic capture, "
        "./contact_sheet_NAME.png for a real one, whose folder is left as it is)",
    )
    p.add_argument(
        "--frames", default=None, help="comma-separated frame indices (default: 8 spread over the sequence)"
    )
    p.add_argument("--masks", action="store_true", help="tile the masks instead of images")
    p.set_defaults(func=cmd_sheet)


def _sheet_path(args: argparse.Namespace, real: bool) -> Path:
    """--out, else CAPTURE/contact_sheet.png for a synthetic capture that can be written,
    else ./contact_sheet_NAME.png: a real capture's folder is the user's (nothing but
    texvocab's cache is written there), and a read-only one takes nothing."""
    if args.out:
        return Path(args.out)
    here = Path(f"contact_sheet_{Path(args.capture).resolve().name}.png")
    if real:
        return here
    if not folder_is_writable(args.capture):
        print(f"capture {args.capture} is read-only: the contact sheet goes to {here.resolve()}")
        return here
    return Path(args.capture) / "contact_sheet.png"


def _is_png(path: Path) -> bool:
    """Whether ``path`` starts with the PNG signature (its first 8 bytes read)."""
    with open(path, "rb") as fh:
        return fh.read(8) == b"\x89PNG\r\n\x1a\n"


def cmd_sheet(args: argparse.Namespace) -> int:
    # late: torch and PIL; `texvocab --help` stays light (module docstring)
    from texvocab.capture import open as open_capture
    from texvocab.io.images import contact_sheet, save_png

    cap = open_capture(args.capture)
    out = _sheet_path(args, cap.masked)
    check_output(out, "file")
    if out.is_file() and not _is_png(out):
        raise TexvocabError(
            f"--out {out}: exists and is not a PNG; expected a new file, or a PNG to replace "
            "(nothing was changed)"
        )
    if args.frames:
        try:
            frames = [int(f) for f in args.frames.split(",")]
        except ValueError:
            raise TexvocabError(
                f"--frames {args.frames}: expected frame numbers separated by commas, e.g. 0,10,20"
            ) from None
    else:
        frames = sorted(set(np.linspace(0, cap.num_frames - 1, min(8, cap.num_frames)).astype(int)))
    bad = [f for f in frames if not 0 <= f < cap.num_frames]
    if bad:
        raise TexvocabError(f"--frames {bad}: the capture has frames 0..{cap.num_frames - 1}")
    get = (lambda v, t: cap.mask(v, t).astype(np.float32)) if args.masks else cap.image
    rows = [[get(v, t) for t in frames] for v in range(cap.num_views)]
    labels = [f"{'train' if t < cap.num_train else 'novel'} {t}" for t in frames]
    save_png(out, contact_sheet(rows, [c.name for c in cap.cameras], labels))
    print(f"contact sheet ({cap.num_views} views x {len(frames)} frames): {out.resolve()}")
    return 0
