"""Progressive rendering: the same view at 1/8, 1/4, 1/2 and full resolution, coarse
levels first, so a viewer can show something at once and refine while the pose is still.

With the surface-guided marcher (``guide="raster"``) a level is every ``level``-th pixel
of the full image in both directions, and each level renders only the pixels the coarser
ones have not: the levels together cost one full-resolution render (its plan, the
rasterisation, is made once), and the last level *is* that render. With the shell
marcher each level renders the camera scaled by 1 / level. The per-pose shell geometry
is built once and shared by all levels; ``cancelled()`` is checked between levels and
between ray chunks, so a newer pose aborts stale work.
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
                       background=(0.0, 0.0, 0.0), shell: ShellGeometry | None = None,
                       index=None) -> Iterator[tuple[int, torch.Tensor, float]]:
    """Yield ``(level, image (H_l, W_l, 3), seconds)`` for each downscale ``level``
    without autograd: with ``settings.guide == "raster"`` the full image's pixels
    [::level, ::level] (H_l = ceil(H / level)), rendered once each across the levels;
    otherwise a render of ``camera.scaled(1 / level)``.

    ``seconds`` is the wall time of that level (the first level includes building the
    shell geometry unless ``shell`` is given). Stops, without yielding the level in
    progress, as soon as ``cancelled()`` returns True. ``index``: the mesh's SurfaceIndex
    for the surface-guided marcher's residual rays (built when needed if not given).
    """
    s = settings or MarchSettings()
    if s.guide == "raster":
        yield from _guided_levels(field, camera, vertices, faces, s, levels, cancelled,
                                  background, shell, index)
        return
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


def _guided_levels(field, camera, vertices, faces, s: MarchSettings, levels, cancelled,
                   background, shell, index=None) -> Iterator[tuple[int, torch.Tensor, float]]:
    """The guided marcher's levels. The coarsest level is a preview: its rays that fall
    back to the shell marcher (silhouette fringes, grazing hits) show their probe's colour
    and are marched with the next level, so the first image needs no shell geometry
    (``shell`` may be a function that builds it)."""
    from texvocab.render.guided import GuidedImage  # it builds on the marcher

    start = time.perf_counter()
    with torch.no_grad():
        image = GuidedImage(field, camera, vertices, faces, s, background, shell, index)
    done = torch.zeros(camera.height, camera.width, dtype=torch.bool)
    for i, level in enumerate(levels):
        if cancelled():
            return
        grid = torch.zeros_like(done)
        grid[::level, ::level] = True
        try:
            with torch.no_grad():  # the first of several levels is a preview (no fallback)
                image.render(grid & ~done, cancelled, defer_fallback=i == 0 and len(levels) > 1)
        except RenderCancelled:
            return
        done |= grid
        rgb = image.rgb.view(camera.height, camera.width, 3)[::level, ::level].clone()
        yield level, rgb, time.perf_counter() - start
        start = time.perf_counter()
