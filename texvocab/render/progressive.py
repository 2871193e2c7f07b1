"""Progressive rendering: the same view at 1/8, 1/4, 1/2 and full resolution, coarse
levels first, so a viewer can show something at once and refine while the pose is still.

With the surface-guided marcher (``guide="raster"``) a level is every ``level``-th pixel
of the full image in both directions, and each level renders only the pixels the coarser
ones have not: the levels together cost one full-resolution render (its plan, the
rasterisation, is made once), and the last level *is* that render. With the shell
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
    [::level, ::level] (H_l = ceil(H / level)), rendered once each across the levels;
    otherwise a render of ``camera.scaled(1 / level)``.

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
            h, w = camera.scaled(1.0 / level).height, camera.scaled(1.0 / level).width
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
    each pixel first rendered at that level (-1 elsewhere). The first of several levels
    (the preview) is shard 0's; later levels' new pixels go round the shards in
    row-major order."""
    done = torch.zeros(height, width, dtype=torch.bool)
    for i, level in enumerate(levels):
        grid = torch.zeros_like(done)
        grid[::level, ::level] = True
        new = (grid & ~done).view(-1).nonzero().squeeze(1)
        owner = torch.full((height * width,), -1, dtype=torch.int8)
        preview = i == 0 and len(levels) > 1
        owner[new] = 0 if preview else (torch.arange(len(new)) % shards).to(torch.int8)
        done |= grid
        yield owner.view(height, width)


def _guided_levels(field, camera, vertices, faces, s: MarchSettings, levels, cancelled,
                   background, shell, index=None, shard=(0, 1)
                   ) -> Iterator[tuple[int, torch.Tensor, float, torch.Tensor]]:
    """The guided marcher's levels. The coarsest level is a preview: its rays that fall
    back to the shell marcher (silhouette fringes, grazing hits) show their probe's colour
    and are marched with the next level, so the first image needs no shell geometry
    (``shell`` may be a function that builds it)."""
    from texvocab.render.guided import GuidedImage  # it builds on the marcher

    start = time.perf_counter()
    with torch.no_grad():
        image = GuidedImage(field, camera, vertices, faces, s, background, shell, index)
    k, n = shard
    mine = torch.zeros(camera.height, camera.width, dtype=torch.bool)  # rendered by this shard
    owners = level_owners(camera.height, camera.width, levels, n)
    for i, (level, owner) in enumerate(zip(levels, owners)):
        if cancelled():
            return
        todo = owner == k
        try:
            with torch.no_grad():  # the first of several levels is a preview (no fallback)
                if todo.any() or image.deferred.any():
                    image.render(todo, cancelled, defer_fallback=i == 0 and len(levels) > 1)
        except RenderCancelled:
            return
        mine |= todo
        rgb = image.rgb.view(camera.height, camera.width, 3)[::level, ::level].clone()
        yield level, rgb, time.perf_counter() - start, mine[::level, ::level].clone()
        start = time.perf_counter()
