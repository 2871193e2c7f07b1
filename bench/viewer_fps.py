"""Frame rate of the viewer's 3D view (texvocab_viewer.gl.scene.SceneRenderer) on a headless OSMesa
context (Mesa llvmpipe, CPU), at 1280x800, 640x400 and 1920x1080: the textured body
alone, with each overlay, with 4x MSAA, and with the pose changing every frame (posing,
normals and the blended vocabulary texture redone per frame). Prints a Markdown table;
"ratio" is each row's frame rate over the plain textured view's at the same size,
measured in the same run.

    .venv/bin/python bench/viewer_fps.py [SOURCE] [--seconds 1.5]

SOURCE: a capture folder or checkpoint (its vocabulary and texture maps); default a
stand-in vocabulary (random training poses, 20 procedural 256² texture maps).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from texvocab_viewer.gl.camera import OrbitCamera  # noqa: E402
from texvocab_viewer.gl.headless import create_headless_context, release  # noqa: E402
from texvocab_viewer.gl.scene import SceneOptions, SceneRenderer  # noqa: E402
from texvocab_viewer.state import ViewerData, ViewerState, load_viewer_data  # noqa: E402

SIZES = ((1280, 800), (640, 400), (1920, 1080))
MODES = {
    "textured": ({}, 0, False),
    "+ part colours": ({"part_colors": True}, 0, False),
    "+ novelty": ({"novelty": True}, 0, False),
    "+ wireframe": ({"wireframe": True}, 0, False),
    "+ skeleton": ({"skeleton": True}, 0, False),
    "+ wireframe + skeleton": ({"wireframe": True, "skeleton": True}, 0, False),
    "textured, MSAA 4x": ({}, 4, False),
    "textured, pose changes every frame": ({}, 0, True),
}


def stand_in_data() -> ViewerData:
    """Default body, a vocabulary of 20 random poses, striped procedural texture maps."""
    from texvocab.body import default_body
    from texvocab.method.vocab import Vocabulary

    rng = np.random.default_rng(0)
    poses = rng.normal(0, 0.2, (20, 24, 3))
    poses[:, 0] = 0
    yy, xx = np.mgrid[0:256, 0:256] / 256.0
    textures = np.stack(
        [
            np.stack(
                [
                    0.5 + 0.5 * np.sin(2 * np.pi * (xx * (3 + t % 5) + t / 7)),
                    0.5 + 0.5 * np.cos(2 * np.pi * yy * (2 + t % 3)),
                    np.full_like(xx, t / 20),
                ],
                -1,
            )
            for t in range(20)
        ]
    )
    return ViewerData(
        default_body(), Vocabulary.build(poses), textures.astype(np.float32), source="stand-in vocabulary"
    )


class Case:
    """One row: a renderer, a state and a camera of its own, and its frame times."""

    def __init__(self, ctx, data, size, flags, samples, moving):
        self.ctx, self.size, self.moving = ctx, size, moving
        self.options = SceneOptions(**flags)
        self.renderer = SceneRenderer(ctx, data, samples=samples)
        self.state = ViewerState(data)
        self.state.apply_preset("walk")
        self.camera = OrbitCamera(yaw=20, distance=2.8)
        self.times: list[float] = []
        self.frame()  # warm-up: uploads, shader compilation
        self.times.clear()

    def frame(self) -> None:
        t0 = time.perf_counter()
        if self.moving:
            self.state.set_joint(16, (0.0, 0.0, -60.0 + 40.0 * np.sin(len(self.times) / 5)))
        self.camera.orbit(1.0, 0.0)
        self.renderer.render(self.state, self.camera, self.size, self.options)
        self.ctx.finish()
        self.times.append(time.perf_counter() - t0)

    def fps(self) -> float:
        """From the median frame time: robust to other processes sharing the CPU."""
        return 1.0 / float(np.median(self.times))


def measure_size(ctx, data, size, seconds: float, rounds: int = 5) -> dict[str, float]:
    """Frames per second of every mode at one size. Modes take turns in ``rounds`` short
    bursts (render + glFinish per frame), so a load change hits all of them alike."""
    cases = {name: Case(ctx, data, size, *spec) for name, spec in MODES.items()}
    for _ in range(rounds):
        for case in cases.values():
            start = time.perf_counter()
            while time.perf_counter() - start < seconds / rounds or len(case.times) < 3:
                case.frame()
    for case in cases.values():
        case.renderer.release()
    return {name: case.fps() for name, case in cases.items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("source", nargs="?", default=None)
    ap.add_argument("--seconds", type=float, default=1.5, help="per row and size (default 1.5)")
    args = ap.parse_args(argv)
    data = load_viewer_data(args.source) if args.source else stand_in_data()
    ctx = create_headless_context()
    threads = os.environ.get("LP_NUM_THREADS", "default")
    print(
        f"# 3D view frame rate: {ctx.info['GL_RENDERER']}, {os.cpu_count()} CPUs "
        f"(LP_NUM_THREADS={threads}), {data.source}, "
        f"{data.body.num_vertices} vertices / {len(data.body.faces)} faces\n"
    )
    print("| size | view | ms / frame | fps | ratio vs textured |")
    print("|---|---|---:|---:|---:|")
    for size in SIZES:
        fps = measure_size(ctx, data, size, args.seconds)
        base = fps["textured"]
        for name, value in fps.items():
            print(
                f"| {size[0]}x{size[1]} | {name} | {1000 / value:.1f} | {value:.1f} | {value / base:.2f} |",
                flush=True,
            )
    release(ctx)
    return 0


if __name__ == "__main__":
    sys.exit(main())
