"""Clip rendering throughput: frames per second of ``texvocab render`` serial (one process,
2 torch threads) against ``--ray`` with N local workers (1 thread each), one run, same
frames, and whether the frames agree.

    .venv/bin/python bench/render_clip.py CKPT [--frames 12] [--workers 2] [--scale 0.5]

The pose sequence is a generated AMASS-layout walk (SMPL-H, 120 fps, Z-up), read like a
user's file. Ray's start-up (local cluster, workers importing torch, the model fetched
from the object store) is timed separately from the frames.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

import numpy as np


def walk_file(path: Path, seconds: float) -> Path:
    """An AMASS-layout (T, 156) walk: upright in Z-up, 1 m/s along +X, knees swinging."""
    rate = 120.0
    t = np.arange(int(seconds * rate) + 1) / rate
    poses = np.zeros((len(t), 156))
    poses[:, 0] = np.pi / 2
    poses[:, 3 * 4] = 0.8 * np.sin(2 * np.pi * t)
    poses[:, 3 * 5] = -0.8 * np.sin(2 * np.pi * t)
    trans = np.stack([t, np.zeros_like(t), np.full_like(t, 0.95)], 1)
    np.savez(path, poses=poses, trans=trans, mocap_framerate=rate)
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("checkpoint")
    ap.add_argument("--frames", type=int, default=12)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--scale", type=float, default=0.5, help="image_scale of the renders")
    args = ap.parse_args(argv)
    import ray
    import torch

    from texvocab.body.pose_files import read_pose_sequence
    from texvocab.io.images import save_png
    from texvocab.pipeline.avatar import load_avatar
    from texvocab.pipeline.clip import frame_cameras
    from texvocab.pipeline.clip_ray import render_frames_ray
    from texvocab.pipeline.clip_worker import FrameWorker
    from texvocab.pipeline.settings import march_settings, render_overrides

    torch.set_num_threads(2)
    tmp = Path(tempfile.mkdtemp())
    av = load_avatar(args.checkpoint, progress=False)
    settings = render_overrides(av.settings, "fast", [f"image_scale={args.scale}"])
    march = march_settings(settings)
    pelvis = av.model.body.rest_joints[0].double().numpy()
    seq = read_pose_sequence(walk_file(tmp / "walk.npz", args.frames / 30), pelvis=pelvis)
    poses, trans = seq.poses[: args.frames], seq.trans[: args.frames]
    ref = np.asarray(av.capture.trans[: av.capture.num_train], dtype=np.float64).mean(0)
    cams = frame_cameras(av.capture.cameras[0], trans + pelvis, ref + pelvis, True, 0.0)
    worker = FrameWorker(av.model, march, settings.render.image_scale, 2)
    worker.render(0, poses[0], trans[0], cams[0])  # warm-up (lazy init), not timed
    t0 = time.perf_counter()
    for i in range(len(poses)):
        save_png(tmp / "serial" / f"frame_{i:05d}.png", worker.render(i, poses[i], trans[i], cams[i])[1])
    serial = time.perf_counter() - t0
    t0 = time.perf_counter()
    ray.init(num_cpus=args.workers, include_dashboard=False, log_to_driver=False, configure_logging=False)
    start = time.perf_counter() - t0
    try:
        (tmp / "ray").mkdir()
        t0 = time.perf_counter()
        render_frames_ray(
            av.model,
            dataclasses.replace(march),
            settings.render.image_scale,
            poses,
            trans,
            cams,
            tmp / "ray",
            workers=args.workers,
            progress=False,
        )
        parallel = time.perf_counter() - t0
    finally:
        ray.shutdown()
    from PIL import Image

    diff = max(
        int(
            np.abs(
                np.asarray(Image.open(tmp / "serial" / p.name)).astype(int)
                - np.asarray(Image.open(p)).astype(int)
            ).max()
        )
        for p in sorted((tmp / "ray").glob("frame_*.png"))
    )
    n = len(poses)
    size = f"{cams[0].width * args.scale:.0f}×{cams[0].height * args.scale:.0f}"
    print(
        f"# clip render: {args.checkpoint}, {n} frames at {size} (fast preset), {args.workers} Ray workers\n"
    )
    print("| path | seconds | frames/s | × serial |")
    print("|---|---|---|---|")
    print(f"| serial (1 process, 2 threads) | {serial:.2f} | {n / serial:.2f} | 1.00 |")
    print(
        f"| --ray, {args.workers} local workers (1 thread each, incl. their start-up) | {parallel:.2f} "
        f"| {n / parallel:.2f} | {serial / parallel:.2f} |"
    )
    print(
        f"\nRay start-up (local cluster): {start:.1f} s, not in the rows above; largest "
        f"pixel difference ray vs serial: {diff} (8-bit levels)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
