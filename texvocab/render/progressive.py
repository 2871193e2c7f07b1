"""Progressive rendering: the same view at 1/8, 1/4, 1/2 and full resolution, coarse
levels first, so a viewer can show something at once and refine while the pose is still.

The per-pose shell geometry is built once and shared by all levels; ``cancelled()`` is
checked between levels and between ray chunks, so a newer pose aborts stale work.
"""
from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import torch

from texvocab.render.coarse import Field
from texvocab.render.marcher import MarchSettings, RenderCancelled, render_image
from texvocab.render.shell import ShellGeometry


def progressive_render(field: Field, camera, vertices, faces,
                       settings: MarchSettings | None = None, levels=(8, 4, 2, 1),
                       cancelled: Callable[[], bool] = lambda: False,
                       background=(0.0, 0.0, 0.0), shell: ShellGeometry | None = None
                       ) -> Iterator[tuple[int, torch.Tensor, float]]:
    """Yield ``(level, image (H_l, W_l, 3), seconds)`` for each downscale ``level``,
    rendering ``camera.scaled(1 / level)`` without autograd.

    ``seconds`` is the wall time of that level (the first level includes building the
    shell geometry unless ``shell`` is given). Stops, without yielding the level in
    progress, as soon as ``cancelled()`` returns True.
    """
    s = settings or MarchSettings()
    start = time.perf_counter()
    if shell is None:
        shell = ShellGeometry.build(vertices, faces, s.shell_width, s.shell_voxel, s.shell_exact)
    for level in levels:
        if cancelled():
            return
        try:
            with torch.no_grad():  # not held across the yield: the caller keeps autograd
                result = render_image(field, camera.scaled(1.0 / level), vertices, faces, s,
                                      background, shell=shell, cancelled=cancelled)
        except RenderCancelled:
            return
        yield level, result.rgb, time.perf_counter() - start
        start = time.perf_counter()
