"""Progressive rendering: the same view at 1/8, 1/4, 1/2 and full resolution, coarse
levels first, so a viewer can show something at once and refine while the pose is still.

With the surface-guided marcher (``guide="raster"``) a level is every ``level``-th pixel
of the full image in both directions. The first of several levels is a preview with a
plan of its own (see :func:`_guided_levels`); after it, each level renders only the
pixels the coarser ones have not: those levels together cost one full-resolution render
(its plan, the rasterisation, is made once), and the last level *is* that render. With
the shell
marcher each level renders the camera scaled by 1 / level. The per-pose shell geometry
is built once and shared by all levels; ``cancelled()`` is checked between levels and
between ray chunks, so a newer pose aborts stale work.

:func:`progressive_shard` renders one of ``n`` interleaved shares of the same levels, so
``n`` processes can split a view (the viewer's render processes): with the guided
marcher each level's new pixels go round the shards in row-major order, except the
first of several levels, the preview, which shard 0 renders alone (it is small, and
splitting it would make every shard build the pose's context and plan before anything
is shown). Each shard yields which pixels of the level it owns; the union over shards
is the level. The shell marcher does not split: shard 0 renders the whole view.
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
    [::level, ::level] (H_l = ceil(H / level)), rendered once each across the levels
    after the preview; otherwise a render of ``camera.scaled(1 / level)``.

    ``seconds`` is the wall time of that level (the first level includes building the
    shell geometry unless ``shell`` is given). Stops, without yielding the level in
    progress, as soon as ``cancelled()`` returns True. ``index``: the mesh's SurfaceIndex
    for the surface-guided marcher's residual rays (built when needed if not given).
    """
    for level, rgb, seconds, _ in progressive_shard(field, camera, vertices, faces, settings,
                                                     levels, cancelled, background, shell,
                                                     index):
        yield level, rgb, seconds


def progressive_shard(field: Field, camera, vertices, faces,
                      settings: MarchSettings | None = None, levels=(8, 4, 2, 1),
                      cancelled: Callable[[], bool] = lambda: False,
                      background=(0.0, 0.0, 0.0), shell: ShellGeometry | None = None,
                      index=None, shard: tuple[int, int] = (0, 1)
                      ) -> Iterator[tuple[int, torch.Tensor, float, torch.Tensor]]:
    """:func:`progressive_render`'s levels as shard ``k`` of ``n`` (``shard = (k, n)``)
    renders them: ``(level, image (H_l, W_l, 3), seconds, owned (H_l, W_l) bool)``, where
    ``owned`` marks the pixels of the level's image this shard rendered (at this level or
    a coarser one; the others are the background colour or zero). See the module
    docstring for who owns what (:func:`level_owners`)."""
    k, n = int(shard[0]), int(shard[1])
    if not 0 <= k < n:
        raise ValueError(f"shard {k} of {n}: expected 0 <= k < n")
    s = settings or MarchSettings()
    if s.guide == "raster":
        yield from _guided_levels(field, camera, vertices, faces, s, levels, cancelled,
                                  background, shell, index, (k, n))
        return
    if k > 0:  # the shell marcher renders scaled cameras: not split
        for level in levels:
            scaled = camera.scaled(1.0 / level)
            h, w = scaled.height, scaled.width
            yield level, torch.zeros(h, w, 3), 0.0, torch.zeros(h, w, dtype=torch.bool)
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
        yield (level, result.rgb, time.perf_counter() - start,
               torch.ones(result.rgb.shape[:2], dtype=torch.bool))
        start = time.perf_counter()


def level_owners(height: int, width: int, levels=(8, 4, 2, 1), shards: int = 1
                 ) -> Iterator[torch.Tensor]:
    """For each of the guided marcher's ``levels``: (H, W) int8, the shard that renders
    each pixel of the full image at that level (-1: none). The first of several levels
    is a preview, shard 0's alone; its pixels are rendered again with the next level.
    Later levels render the pixels of their grid not rendered before, round the shards
    in row-major order."""
    done = torch.zeros(height, width, dtype=torch.bool)
    for i, level in enumerate(levels):
        grid = torch.zeros_like(done)
        grid[::level, ::level] = True
        owner = torch.full((height * width,), -1, dtype=torch.int8)
        if i == 0 and len(levels) > 1:
            owner[grid.view(-1)] = 0
        else:
            new = (grid & ~done).view(-1).nonzero().squeeze(1)
            owner[new] = (torch.arange(len(new)) % shards).to(torch.int8)
            done |= grid
        yield owner.view(height, width)


def _guided_levels(field, camera, vertices, faces, s: MarchSettings, levels, cancelled,
                   background, shell, index=None, shard=(0, 1)
                   ) -> Iterator[tuple[int, torch.Tensor, float, torch.Tensor]]:
    """The guided marcher's levels. The first of several levels is a preview of its own:
    the camera of every ``level``-th pixel (``Camera.every``: the same rays as
    ``image[::level, ::level]``) with its own small plan, and rays that would fall back
    to the shell marcher (silhouette fringes, grazing hits) shown with their probe's
    colour. So the first image needs neither the full image's plan nor any shell
    geometry (``shell`` may be a function that builds it); the next level renders those
    pixels again with the rest (1/64 more rays at levels 8, 4, 2, 1)."""
    from texvocab.render.guided import GuidedImage  # it builds on the marcher

    start = time.perf_counter()
    k, n = shard
    H, W = camera.height, camera.width
    mine = torch.zeros(H, W, dtype=torch.bool)  # rendered by this shard
    image = None  # the full image's, built after the preview
    for i, (level, owner) in enumerate(zip(levels, level_owners(H, W, levels, n))):
        if cancelled():
            return
        preview = i == 0 and len(levels) > 1
        try:
            with torch.no_grad():  # not held across the yield: the caller keeps autograd
                if preview:
                    rgb = _preview(field, camera.every(level), vertices, faces, s, background,
                                   shell, index, cancelled, k == 0)
                else:
                    if image is None:
                        image = GuidedImage(field, camera, vertices, faces, s, background,
                                            shell, index)
                    todo = owner == k
                    if todo.any():
                        image.render(todo, cancelled)
                    mine |= todo
                    rgb = image.rgb.view(H, W, 3)[::level, ::level].clone()
        except RenderCancelled:
            return
        owned = owner[::level, ::level] == k if preview else mine[::level, ::level].clone()
        yield level, rgb, time.perf_counter() - start, owned
        start = time.perf_counter()


def _preview(field, camera, vertices, faces, s, background, shell, index, cancelled,
             render: bool) -> torch.Tensor:
    """The image (H, W, 3) of ``camera`` with fallback rays left at their probe's colour
    (the background when not ``render``: another shard's preview)."""
    from texvocab.render.guided import GuidedImage

    if not render:
        return torch.as_tensor(background, dtype=torch.float32).expand(
            camera.height, camera.width, 3).clone()
    small = GuidedImage(field, camera, vertices, faces, s, background, shell, index)
    small.render(None, cancelled, defer_fallback=True)
    return small.rgb.view(camera.height, camera.width, 3).clone()
