"""``texvocab prepare`` (texture maps, Sec. 3.2) and ``texvocab vocab`` (Sec. 3.3–3.4).

build_parser imports this module, so the commands import what they run (torch) inside
their functions: ``texvocab --help`` stays light."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from texvocab.errors import TexvocabError
from texvocab.io.outputs import check_output
from texvocab.pipeline.run_folder import check_run_folder


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


def _open(args):
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

    cap = _open(args)
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
    cap = _open(args)
    if cap.num_train == 0:
        raise TexvocabError(f"{args.capture}: no training frames to build a vocabulary from")
    pose = parse_pose(args.pose, cap)
    vocab = Vocabulary.build(
        cap.poses[: cap.num_train],
        args.strategy,
        args.keys,
        args.k,
        args.weighting,
        args.min_distance,
        args.pose_condition,
    )
    print(f"pose: {args.pose}   training frames: {cap.num_train}")
    print(vocab.format_query(pose))
    return 0


def add_train_parsers(sub, add_smpl) -> None:
    p = sub.add_parser(
        "train",
        help="train an avatar on a capture",
        description="Fit the TexVocab avatar to a capture's training frames "
        "and views; checkpoints go to OUT/checkpoint.pt (atomic, "
        "at intervals and at the end).",
    )
    p.add_argument("capture", help="capture folder")
    p.add_argument("--out", required=True, help="run folder (checkpoint, logs)")
    p.add_argument("--iterations", type=int, default=None, help="steps (default: settings)")
    p.add_argument(
        "--resume", action="store_true", help="continue from OUT/checkpoint.pt (--iterations N extends it)"
    )
    p.add_argument(
        "--ddp",
        type=int,
        default=None,
        metavar="N",
        help="data-parallel training on N local processes (gloo on CPU); under "
        "torchrun the group comes from torchrun instead (README, 'Training')",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the run in OUT (refused without it when OUT holds a checkpoint)",
    )
    p.add_argument(
        "--preset",
        choices=("fast", "balanced", "quality"),
        default=None,
        help="speed/accuracy preset (bench/tradeoff.py); --set applies after it",
    )
    p.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a setting, e.g. --set vocab.strategy=joint --set field.hidden=64",
    )
    p.add_argument(
        "--train-frames",
        type=int,
        default=None,
        help="leading training frames (default: the capture's split)",
    )
    add_smpl(p)
    p.set_defaults(func=cmd_train)

    p = sub.add_parser(
        "eval",
        help="evaluate a checkpoint (PSNR/SSIM/LPIPS/FID/KID, image grid)",
        description="Render the held-out views (eval_views) of every novel frame, "
        "of as many training frames (evenly spread) and, for "
        "synthetic captures, of generated novel poses; write "
        "metrics.md (mean ± standard error, image counts), "
        "metrics.json (per image, mean and sem) and grid PNGs.",
    )
    p.add_argument("checkpoint", help="checkpoint.pt written by texvocab train")
    p.add_argument("capture", help="capture folder (the one trained on)")
    p.add_argument("--out", default=None, help="report folder (default: next to the checkpoint)")
    p.add_argument(
        "--per-set",
        type=int,
        default=None,
        metavar="N",
        help="only N frames per set, evenly spread, for a quick look (default: all "
        "novel frames and as many training frames)",
    )
    p.add_argument(
        "--preset",
        choices=("fast", "balanced", "quality"),
        default=None,
        help="render preset (render knobs only; the rest is in the checkpoint)",
    )
    p.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a render knob, e.g. --set render.coarse_samples=24",
    )
    add_smpl(p)
    p.set_defaults(func=cmd_eval)


def cmd_train(args: argparse.Namespace) -> int:
    # late: torch (module docstring)
    from texvocab.pipeline.settings import Settings, preset_overrides
    from texvocab.pipeline.train import Trainer

    if args.ddp is not None and args.ddp < 1:
        raise TexvocabError(f"--ddp {args.ddp}: expected a number of processes >= 1")
    pre = preset_overrides(args.preset) if args.preset else []
    steps = [] if args.iterations is None else [f"train.iterations={args.iterations}"]
    settings = Settings().with_overrides(pre + args.overrides + steps)
    out = Path(args.out)
    check_run_folder(out, args.resume, args.overwrite)
    check_output(out, "folder")
    cap = _open(args)
    if args.ddp is not None or _under_torchrun():
        return _train_parallel(args, settings, out)
    trainer = Trainer(cap, settings, out)
    if args.resume and trainer.resume():
        print(f"resumed at step {trainer.step} from {trainer.checkpoint_path}")
    logs = trainer.run()
    last = logs[-1] if logs else {}
    print(
        f"step {trainer.step}: loss {last.get('loss', float('nan')):.4f}, batch PSNR "
        f"{last.get('psnr', float('nan')):.2f} dB; checkpoint {trainer.checkpoint_path}"
    )
    return 0


def _under_torchrun() -> bool:
    from texvocab.pipeline.ddp import under_torchrun  # late: torch

    return under_torchrun()


def _train_parallel(args: argparse.Namespace, settings, out: Path) -> int:
    """--ddp N (local processes) or a torchrun process: texvocab.pipeline.ddp."""
    import torch.distributed as dist

    from texvocab.io.checkpoint import load_checkpoint
    from texvocab.pipeline import ddp

    job = {
        "capture": args.capture,
        "settings": settings,
        "out": str(out),
        "resume": args.resume,
        "smpl": args.smpl,
        "train_frames": args.train_frames,
    }
    if ddp.under_torchrun():
        dist.init_process_group(ddp.backend(), init_method="env://")
        try:
            world = dist.get_world_size()
            ddp.run_process(job)
            dist.barrier()  # leave together: rank 0 may still be writing the checkpoint
            lead = dist.get_rank() == 0
        finally:
            dist.destroy_process_group()
        if not lead:
            return 0
    else:
        world = args.ddp
        ddp.spawn(world, job)
    ck = load_checkpoint(out / "checkpoint.pt")
    print(f"step {ck['step']} on {world} processes; checkpoint {out / 'checkpoint.pt'}")
    return 0


def cmd_eval(args: argparse.Namespace) -> int:
    # late: torch (module docstring)
    from texvocab.pipeline.avatar import load_avatar
    from texvocab.pipeline.evaluate import build_sets, evaluate_sets, write_report
    from texvocab.pipeline.settings import march_settings, render_overrides
    from texvocab.pipeline.split import split_note

    if args.per_set is not None and args.per_set < 1:
        raise TexvocabError(f"--per-set must be at least 1, got {args.per_set}")
    out = Path(args.out) if args.out else Path(args.checkpoint).parent / "eval"
    check_output(out, "folder", flag="--out" if args.out else "report folder (choose one with --out)")
    avatar = load_avatar(args.checkpoint, _open(args))
    model, ck = avatar.model, avatar.checkpoint
    settings = render_overrides(avatar.settings, args.preset, args.overrides)
    sets = build_sets(avatar.capture, settings, args.per_set)
    t0 = time.perf_counter()
    table, records, grids = evaluate_sets(
        model, sets, march_settings(settings), scale=settings.render.image_scale, progress=True
    )
    paths = write_report(
        out,
        table,
        records,
        grids,
        {
            "checkpoint": str(args.checkpoint),
            "step": int(ck["step"]),
            "capture": str(args.capture),
            "settings": settings.to_dict(),
            "split": split_note(avatar.capture),
        },
    )
    print(paths[0].read_text())
    print(
        f"evaluated {sum(len(v) for v in sets.values())} images in "
        f"{time.perf_counter() - t0:.1f} s; report in {out.resolve()}"
    )
    return 0
