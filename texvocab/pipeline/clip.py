"""A pose sequence rendered to a video: one neural render per pose from a capture camera
that follows the body (or orbits it), frames cached as PNGs so an interrupted render
resumes where it stopped, then an MP4 (H.264 through the ffmpeg that ``imageio-ffmpeg``
ships) or the PNG sequence itself.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from texvocab.capture.camera import Camera
from texvocab.errors import TexvocabError
from texvocab.io.images import atomic_write_bytes, save_png
from texvocab.io.stop_flag import raise_if_stopped
from texvocab.io.temp_files import sweep_stale, temp_name

KEY_FILE = "clip.json"


@dataclass
class ClipSpec:
    """What a clip is rendered from; two renders with equal specs share cached frames.

    checkpoint, poses: absolute paths (and their sizes and modification times, so a
    retrained checkpoint or an edited pose file never reuses stale frames); view: capture
    camera index; orbit: turns of the camera about the body over the clip (0: fixed);
    follow: the camera moves with the body's root; fps; scale: image scale; knobs: the
    render settings."""

    checkpoint: str
    poses: str
    view: int
    orbit: float
    follow: bool
    fps: float
    scale: float
    knobs: dict
    stamps: dict

    @classmethod
    def make(cls, checkpoint, poses, view, orbit, follow, fps, scale, knobs) -> ClipSpec:
        stamps = {
            str(p): [os.stat(p).st_size, os.stat(p).st_mtime_ns] for p in (Path(checkpoint), Path(poses))
        }
        return cls(
            str(Path(checkpoint).resolve()),
            str(Path(poses).resolve()),
            int(view),
            float(orbit),
            bool(follow),
            float(fps),
            float(scale),
            dict(knobs),
            stamps,
        )

    def digest(self) -> str:
        return hashlib.sha1(json.dumps(asdict(self), sort_keys=True).encode()).hexdigest()[:16]


def frames_dir(out: Path) -> Path:
    """Where the frames of ``out`` go: ``clip.frames/`` beside ``clip.mp4``; ``out`` itself
    for a PNG sequence (an ``out`` without the .mp4 suffix)."""
    return out.with_name(out.stem + ".frames") if out.suffix.lower() == ".mp4" else out


def prepare_frames_dir(folder: Path, spec: ClipSpec, overwrite: bool) -> int:
    """Create or reuse ``folder`` for ``spec``; returns how many frames are already there.
    A folder holding another render's frames is replaced only with ``overwrite`` (and only
    its frame files and key); any other non-empty folder is never touched."""
    key = folder / KEY_FILE
    if folder.exists() and any(folder.iterdir()):
        if not key.is_file():
            raise TexvocabError(
                f"{folder}: exists and is not a texvocab frame folder (no {KEY_FILE}); choose another --out"
            )
        try:
            old = json.loads(key.read_text())
        except (OSError, ValueError):
            old = {}
        if old.get("digest") != spec.digest():
            if not overwrite:
                diff = [k for k, v in asdict(spec).items() if old.get("spec", {}).get(k) != v]
                raise TexvocabError(
                    f"{folder}: holds frames of another render ({', '.join(diff)}"
                    " differ); pass --overwrite to replace them, or another --out"
                )
            for f in folder.glob("frame_*.png"):
                f.unlink()
    folder.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(
        key,
        lambda t: Path(t).write_text(json.dumps({"digest": spec.digest(), "spec": asdict(spec)}, indent=1)),
    )
    return sum(1 for _ in folder.glob("frame_*.png"))


def follow_camera(camera: Camera, shift: np.ndarray) -> Camera:
    """``camera`` moved by ``shift`` (3,) in the world (same orientation)."""
    centre = camera.center + np.asarray(shift, dtype=np.float64)
    return Camera(
        camera.K, camera.R, -camera.R @ centre, camera.width, camera.height, camera.dist, camera.name
    )


def orbit_camera(camera: Camera, pivot: np.ndarray, angle: float) -> Camera:
    """``camera`` turned by ``angle`` (radians) about the vertical (+Y) axis through
    ``pivot`` (3,), still looking the same way relative to the body."""
    c, s = math.cos(angle), math.sin(angle)
    turn = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    centre = pivot + turn @ (camera.center - pivot)
    R = camera.R @ turn.T
    return Camera(camera.K, R, -R @ centre, camera.width, camera.height, camera.dist, camera.name)


def frame_cameras(
    camera: Camera, roots: np.ndarray, reference: np.ndarray, follow: bool, orbit: float
) -> list[Camera]:
    """One camera per frame: ``camera`` shifted by each root (T, 3) minus ``reference``
    (3,) when ``follow``, turned about the root by ``orbit`` turns over the clip."""
    cams = []
    for i, root in enumerate(roots):
        cam = follow_camera(camera, root - reference) if follow else camera
        if orbit:
            cam = orbit_camera(cam, root, 2 * math.pi * orbit * i / max(len(roots), 1))
        cams.append(cam)
    return cams


def render_frames(
    render, poses: np.ndarray, trans: np.ndarray, cameras: list[Camera], folder: Path, progress: bool = True
) -> list[Path]:
    """``render(pose, trans, camera) -> (H, W, 3) uint8`` for every frame not yet in
    ``folder``; frames written atomically as frame_00000.png, ..."""
    paths = [folder / f"frame_{i:05d}.png" for i in range(len(poses))]
    todo = [i for i, p in enumerate(paths) if not p.is_file()]
    bar = tqdm(
        total=len(paths), initial=len(paths) - len(todo), unit="frame", desc="render", disable=not progress
    )
    for i in todo:
        save_png(paths[i], render(poses[i], trans[i], cameras[i]))
        bar.update(1)
    bar.close()
    return paths


def write_mp4(paths: list[Path], out: Path, fps: float) -> Path:
    """H.264 MP4 of PNG frames (all one size), written to a temporary file in ``out``'s
    folder and moved into place. Odd sizes are padded by a pixel (yuv420p needs even)."""
    import imageio_ffmpeg
    from PIL import Image

    first = np.asarray(Image.open(paths[0]).convert("RGB"))
    h, w = first.shape[:2]
    H, W = h + h % 2, w + w % 2
    sweep_stale(out.parent)
    tmp = temp_name(out)
    writer = imageio_ffmpeg.write_frames(
        str(tmp),
        (W, H),
        fps=fps,
        codec="libx264",
        pix_fmt_out="yuv420p",
        macro_block_size=2,
        quality=8,
        ffmpeg_log_level="error",
    )
    try:
        writer.send(None)
        for p in paths:
            img = np.asarray(Image.open(p).convert("RGB"))
            if img.shape[:2] != (h, w):
                raise TexvocabError(f"{p}: {img.shape[1]}x{img.shape[0]}, expected {w}x{h}")
            frame = np.zeros((H, W, 3), np.uint8)
            frame[:h, :w] = img
            writer.send(np.ascontiguousarray(frame))
        writer.close()
        raise_if_stopped()  # a stop signal that a library swallowed (texvocab.io.stop_flag)
        os.replace(tmp, out)
    finally:
        if tmp.exists():
            tmp.unlink()
    return out


def read_video_info(path: Path) -> tuple[int, tuple[int, int], float]:
    """(frames, (width, height), fps) of a video, by decoding it."""
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(str(path))
    meta = reader.__next__()
    n = sum(1 for _ in reader)
    return n, tuple(meta["size"]), float(meta["fps"])
