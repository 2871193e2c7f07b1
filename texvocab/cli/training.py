"""``texvocab train`` (Sec. 3.5; one process, ``--ddp N`` or torchrun) and ``texvocab eval``.

build_parser imports this module, so the commands import what they run (torch) inside
their functions: ``texvocab --help`` stays light."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from texvocab.cli.method import open_from_args
from texvocab.errors import TexvocabError
from texvocab.io.outputs import check_output
from texvocab.pipeline.run_folder import check_run_folder


def add_settings_arguments(p: argparse.ArgumentParser, preset_help: str, set_help: str) -> None:
    """``--preset fast|balanced|quality`` and ``--set KEY=VALUE`` (repeatable, into
    ``args.overrides``) of ``train``, ``eval`` and ``render``."""
    p.add_argument("--preset", choices=("fast", "balanced", "quality"), default=None, help=preset_help)
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE", help=set_help)


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
        "--other-capture",
        action="store_true",
        help="with --resume: continue a checkpoint trained on another capture than CAPTURE "
        "(other frames, views or calibration; refused without it), with one warning line",
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
    add_settings_arguments(
        p,
        "speed/accuracy preset (bench/tradeoff.py); --set applies after it",
        "override a setting, e.g. --set vocab.strategy=joint --set field.hidden=64",
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
        "--other-capture",
        action="store_true",
        help="evaluate on CAPTURE though it is not the capture the checkpoint was trained "
        "on (other frames, views or calibration; refused without it), with one warning line",
    )
    p.add_argument(
        "--per-set",
        type=int,
        default=None,
        metavar="N",
        help="only N frames per set, evenly spread, for a quick look (default: all "
        "novel frames and as many training frames)",
    )
    add_settings_arguments(
        p,
        "render preset (render knobs only; the rest is in the checkpoint)",
        "override a render knob, e.g. --set render.coarse_samples=24",
    )
    add_smpl(p)
    p.set_defaults(func=cmd_eval)


def cmd_train(args: argparse.Namespace) -> int:
    # late: torch (module docstring)
    from texvocab.pipeline.settings import Settings, preset_overrides
    from texvocab.pipeline.train import Trainer

    if args.ddp is not None and args.ddp < 1:
        raise TexvocabError(f"--ddp {args.ddp}: expected a number of processes >= 1")
    if args.other_capture and not args.resume:
        raise TexvocabError("--other-capture applies with --resume (a checkpoint to continue on CAPTURE)")
    pre = preset_overrides(args.preset) if args.preset else []
    steps = [] if args.iterations is None else [f"train.iterations={args.iterations}"]
    settings = Settings().with_overrides(pre + args.overrides + steps)
    out = Path(args.out)
    check_run_folder(out, args.resume, args.overwrite)
    check_output(out, "folder")
    cap = open_from_args(args)
    if args.resume and not args.other_capture and (out / "checkpoint.pt").is_file():
        _refuse_other_capture(out / "checkpoint.pt", cap)  # before the texture maps are built
    if args.ddp is not None or _under_torchrun():
        return _train_parallel(args, settings, out)
    trainer = Trainer(cap, settings, out)
    if args.resume and trainer.resume(args.other_capture):
        print(f"resumed at step {trainer.step} from {trainer.checkpoint_path}")
    logs = trainer.run()
    last = logs[-1] if logs else {}
    print(
        f"step {trainer.step}: loss {last.get('loss', float('nan')):.4f}, batch PSNR "
        f"{last.get('psnr', float('nan')):.2f} dB; checkpoint {trainer.checkpoint_path}"
    )
    return 0


def _refuse_other_capture(checkpoint: Path, cap) -> None:
    """TexvocabError when ``checkpoint`` was trained on another capture than ``cap``."""
    from texvocab.capture.identity import check_capture_identity  # late: torch
    from texvocab.io.checkpoint import load_checkpoint

    check_capture_identity(load_checkpoint(checkpoint), cap, checkpoint)


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
        "other_capture": args.other_capture,
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
    avatar = load_avatar(args.checkpoint, open_from_args(args), other_capture=args.other_capture)
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
