"""``texvocab render CKPT --poses FILE --out clip.mp4``: a pose sequence (SMPL, AMASS
SMPL-H or SMPL-X) driving a trained avatar, as an MP4 or a PNG sequence."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from texvocab.cli.training import add_settings_arguments
from texvocab.errors import TexvocabError
from texvocab.io.outputs import check_output
from texvocab.pipeline.root_choice import ROOT_HELP, ROOTS


def add_render_parser(sub, add_smpl) -> None:
    p = sub.add_parser(
        "render",
        help="render a pose sequence with a trained avatar to a video",
        description="Drive a trained avatar with a pose file (SMPL (T, 24, 3) / "
        "(T, 72), AMASS SMPL-H (T, 156), SMPL-X (T, 165)) and write "
        "an MP4 (--out clip.mp4) or a PNG sequence (--out FOLDER). "
        "Frames are cached beside the video (clip.frames/): run the "
        "same command again to resume an interrupted render.",
    )
    p.add_argument("checkpoint", help="trained checkpoint (checkpoint.pt)")
    p.add_argument("--poses", required=True, metavar="FILE.npz", help="pose sequence")
    p.add_argument("--out", required=True, help="clip.mp4, or a folder for PNG frames")
    p.add_argument(
        "--camera", type=int, default=0, metavar="N", help="capture camera to render from (default 0)"
    )
    p.add_argument(
        "--no-follow",
        dest="follow",
        action="store_false",
        help="keep the camera where the capture had it (default: it moves with the "
        "body's root, as a follow camera)",
    )
    p.add_argument(
        "--orbit",
        type=float,
        default=0.0,
        metavar="TURNS",
        help="turn the camera about the body this many times over the clip",
    )
    p.add_argument(
        "--panels",
        default="neural",
        metavar="LIST",
        help="comma-separated panels side by side: neural (the avatar), vocab (the "
        "body with the pose's blended vocabulary texture), novelty (each "
        "part's distance to its nearest key); default: neural",
    )
    p.add_argument(
        "--fps",
        type=float,
        default=30.0,
        help="frame rate: files that state theirs (AMASS) are resampled to it",
    )
    p.add_argument(
        "--root",
        choices=(*ROOTS, "zero", "keep"),
        default="floor",
        help=ROOT_HELP + "; zero: the root orientation and translation dropped; keep: recorded",
    )
    p.add_argument(
        "--up",
        choices=("auto", "y", "z"),
        default="auto",
        help="the file's up axis (auto: Z for AMASS SMPL-H/SMPL-X, else Y)",
    )
    p.add_argument(
        "--place",
        choices=["auto", "capture", "keep"],
        default="auto",
        help="capture: turn the motion into the capture's world (its up axis, the first "
        "frame facing the camera, standing where the capture's subject stands); keep: as "
        "the file has it; auto: capture when the capture's up axis is not +Y (ZJU-MoCap)",
    )
    p.add_argument(
        "--frames", default=None, metavar="A:B", help="only frames A..B-1 of the (resampled) sequence"
    )
    p.add_argument(
        "--capture",
        metavar="FOLDER",
        default=None,
        help="the capture the checkpoint was trained on (default: the one it records)",
    )
    p.add_argument(
        "--other-capture",
        action="store_true",
        help="render on a capture the checkpoint was not trained on (other frames, views "
        "or calibration; refused without it), with one warning line",
    )
    add_settings_arguments(
        p,
        "render preset (render knobs only; the rest is in the checkpoint)",
        "override a render knob, e.g. --set render.image_scale=0.5",
    )
    p.add_argument(
        "--ray",
        nargs="?",
        const="local",
        default=None,
        metavar="ADDRESS",
        help="render frames in parallel as Ray tasks: a local Ray with --workers "
        "workers, or the cluster at ADDRESS (pip install 'texvocab[scale]')",
    )
    p.add_argument("--workers", type=int, default=2, help="Ray workers (default 2)")
    p.add_argument(
        "--overwrite", action="store_true", help="replace frames cached by a render with other settings"
    )
    add_smpl(p)
    p.set_defaults(func=cmd_render)


def _frame_range(spec: str | None, n: int) -> range:
    if spec is None:
        return range(n)
    a, sep, b = spec.partition(":")
    try:
        lo, hi = int(a or 0), int(b) if b else n
    except ValueError:
        raise TexvocabError(f"--frames {spec!r}: expected A:B (frame numbers)") from None
    if not sep or not 0 <= lo < hi <= n:
        raise TexvocabError(f"--frames {spec!r}: expected A:B with 0 <= A < B <= {n}")
    return range(lo, hi)


def cmd_render(args: argparse.Namespace) -> int:
    # late: torch (module docstring of texvocab.cli.main)
    import numpy as np

    from texvocab.body.pose_files import MAX_FPS, read_pose_sequence
    from texvocab.pipeline.avatar import load_avatar
    from texvocab.pipeline.clip import (
        ClipSpec,
        frame_cameras,
        frames_dir,
        prepare_frames_dir,
        render_frames,
        write_mp4,
    )
    from texvocab.pipeline.clip_placement import needs_placing, place_motion
    from texvocab.pipeline.clip_worker import FrameWorker
    from texvocab.pipeline.settings import RENDER_KNOBS, march_settings, render_overrides

    out = Path(args.out)
    if not 0 < args.fps <= MAX_FPS:
        raise TexvocabError(f"--fps {args.fps:g}: expected a frame rate in (0, {MAX_FPS:g}]")
    if args.workers < 1:
        raise TexvocabError(f"--workers {args.workers}: expected at least 1")
    panels = [p.strip() for p in args.panels.split(",") if p.strip()]
    known = ("neural", "vocab", "novelty")
    if not panels or any(p not in known for p in panels) or len(set(panels)) < len(panels):
        raise TexvocabError(
            f"--panels {args.panels!r}: expected a comma-separated list of distinct {', '.join(known)}"
        )
    gl = [p for p in panels if p != "neural"]
    if gl and args.ray is not None:
        raise TexvocabError(
            f"--panels {args.panels}: the {', '.join(gl)} panels are drawn by "
            "this process's GL; use --ray with --panels neural"
        )
    if args.ray is not None:
        from texvocab.pipeline.clip_ray import _ray

        _ray()  # refuse before any work when Ray is missing
    if not Path(args.poses).is_file():
        raise TexvocabError(f"--poses {args.poses}: no such file")
    if out.suffix.lower() not in ("", ".mp4"):
        raise TexvocabError(f"--out {out}: expected a .mp4 file or a folder for PNG frames")
    check_output(out, "file" if out.suffix.lower() == ".mp4" else "folder")  # clip.frames/ beside it
    if out.suffix.lower() == ".mp4" and out.exists() and not args.overwrite:
        raise TexvocabError(f"--out {out}: exists; pass --overwrite to replace it")
    data = None
    if gl:  # the viewer's data: the avatar plus what its 3D view draws
        from texvocab_viewer.state import load_viewer_data  # late: torch, only for GL panels

        data = load_viewer_data(args.checkpoint, args.smpl, args.capture, args.other_capture)
        cap, model, trained = data.capture, data.model, data.settings
    else:
        cap = None
        if args.capture:
            from texvocab.body import load_body
            from texvocab.capture import open as open_capture

            cap = open_capture(args.capture, body=load_body(args.smpl))
        avatar = load_avatar(args.checkpoint, cap, smpl=args.smpl, other_capture=args.other_capture)
        cap, model, trained = avatar.capture, avatar.model, avatar.settings
    if not 0 <= args.camera < cap.num_views:
        raise TexvocabError(f"--camera {args.camera}: the capture has views 0..{cap.num_views - 1}")
    settings = render_overrides(trained, args.preset, args.overrides)
    pelvis = model.body.rest_joints[0].double().numpy()
    read_root = "zero" if args.root == "zero" else "keep"
    seq = read_pose_sequence(args.poses, fps=args.fps, up=args.up, root=read_root, pelvis=pelvis)
    keep = _frame_range(args.frames, len(seq))
    poses, trans = seq.poses[keep.start : keep.stop], seq.trans[keep.start : keep.stop]
    placed = needs_placing(cap, args.place)
    root = "recorded" if args.root in ("zero", "keep") else args.root
    # the motion into the capture's world (its up axis, facing the camera), stood by --root
    poses, trans = place_motion(poses, trans, pelvis, cap, cap.cameras[args.camera], root, args.place)
    fps = seq.fps or args.fps
    knobs = {k: getattr(settings.render, k) for k in RENDER_KNOBS}
    spec = ClipSpec.make(
        args.checkpoint,
        args.poses,
        args.camera,
        args.orbit,
        args.follow,
        fps,
        settings.render.image_scale,
        {
            **knobs,
            "frames": [keep.start, keep.stop],
            "up": args.up,
            "root": args.root,
            "panels": panels,
            **({"placed": True} if placed else {}),
        },
    )
    folder = frames_dir(out)
    cached = prepare_frames_dir(folder, spec, args.overwrite)
    reference = np.asarray(cap.trans[: cap.num_train], dtype=np.float64).mean(0)
    cams = frame_cameras(
        cap.cameras[args.camera],
        trans.astype(np.float64) + pelvis,
        reference + pelvis,
        args.follow,
        args.orbit,
    )
    march = march_settings(settings)
    t0 = time.perf_counter()
    if args.ray is None:
        import torch

        worker = FrameWorker(model, march, settings.render.image_scale, torch.get_num_threads())
        extra = None
        if gl:
            from texvocab_viewer.export.clip_panels import GLPanels, side_by_side  # late: GL

            extra = GLPanels(data, panels)

        def frame(p, t, c):
            images = {"neural": worker.render(0, p, t, c)[1]} if "neural" in panels else {}
            if extra is not None:
                images.update(zip(extra.panels, extra.render(p, t, c), strict=True))
            return images["neural"] if not gl else side_by_side([images[n] for n in panels])

        try:
            paths = render_frames(frame, poses, trans, cams, folder)
        finally:
            if extra is not None:
                extra.close()
    else:
        from texvocab.pipeline.clip_ray import render_frames_ray

        paths = render_frames_ray(
            model,
            march,
            settings.render.image_scale,
            poses,
            trans,
            cams,
            folder,
            None if args.ray == "local" else args.ray,
            args.workers,
        )
    seconds = time.perf_counter() - t0
    done = len(paths) - cached
    print(
        f"rendered {done} frames ({cached} cached) in {seconds:.1f} s"
        + (f", {seconds / done:.2f} s per frame" if done else "")
        + f"; {seq.layout} poses at {fps:g} fps"
    )
    if out.suffix.lower() == ".mp4":
        write_mp4(paths, out, fps)
        print(f"  video:  {out.resolve()} ({len(paths)} frames, {len(paths) / fps:.1f} s)")
    print(f"  frames: {folder.resolve()}/")
    return 0
