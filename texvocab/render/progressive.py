"""Progressive rendering: the same view at 1/8, 1/4, 1/2 and full resolution, coarse
levels first, so a viewer can show something at once and refine while the pose is still.

Each render path has its levels (:mod:`texvocab.render.paths`). With the surface-guided
marcher (``guide="raster"``, :mod:`texvocab.render.guided.levels`) a level is every
``level``-th pixel of the full image in both directions. The first of several levels is a
preview with a plan of its own; after it, each level renders only the pixels the coarser
ones have not: those levels together cost one full-resolution render (its plan, the
rasterisation, is made once), and the last level *is* that render. With the shell marcher
(:func:`texvocab.render.shell.march.shell_levels`) each level renders the camera scaled by
1 / level. The per-pose shell geometry
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

from collections.abc import Callable, Iterator

import torch

from texvocab.render.paths import render_path
from texvocab.render.settings import MarchSettings
from texvocab.render.shell.geometry import ShellGeometry
from texvocab.render.volume.field import Field


def progressive_render(
    field: Field,
    camera,
    vertices,
    faces,
    settings: MarchSettings | None = None,
    levels=(8, 4, 2, 1),
    cancelled: Callable[[], bool] = lambda: False,
    background=(0.0, 0.0, 0.0),
    shell: ShellGeometry | None = None,
    index=None,
) -> Iterator[tuple[int, torch.Tensor, float]]:
    """Yield ``(level, image (H_l, W_l, 3), seconds)`` for each downscale ``level``
    without autograd: with ``settings.guide == "raster"`` the full image's pixels
    [::level, ::level] (H_l = ceil(H / level)), rendered once each across the levels
    after the preview; otherwise a render of ``camera.scaled(1 / level)``.

    ``seconds`` is the wall time of that level (the first level includes building the
    shell geometry unless ``shell`` is given). Stops, without yielding the level in
    progress, as soon as ``cancelled()`` returns True. ``index``: the mesh's SurfaceIndex
    for the surface-guided marcher's residual rays (built when needed if not given).
    """
    for level, rgb, seconds, _ in progressive_shard(
        field, camera, vertices, faces, settings, levels, cancelled, background, shell, index
    ):
        yield level, rgb, seconds


def progressive_shard(
    field: Field,
    camera,
    vertices,
    faces,
    settings: MarchSettings | None = None,
    levels=(8, 4, 2, 1),
    cancelled: Callable[[], bool] = lambda: False,
    background=(0.0, 0.0, 0.0),
    shell: ShellGeometry | None = None,
    index=None,
    shard: tuple[int, int] = (0, 1),
) -> Iterator[tuple[int, torch.Tensor, float, torch.Tensor]]:
    """:func:`progressive_render`'s levels as shard ``k`` of ``n`` (``shard = (k, n)``)
    renders them: ``(level, image (H_l, W_l, 3), seconds, owned (H_l, W_l) bool)``, where
    ``owned`` marks the pixels of the level's image this shard rendered (at this level or
    a coarser one; the others are the background colour or zero). See the module
    docstring for who owns what (:func:`~texvocab.render.guided.levels.level_owners`); the
    levels are the render path's (:attr:`~texvocab.render.paths.RenderPath.levels`)."""
    k, n = int(shard[0]), int(shard[1])
    if not 0 <= k < n:
        raise ValueError(f"shard {k} of {n}: expected 0 <= k < n")
    s = settings or MarchSettings()
    yield from render_path(s.guide).levels(
        field, camera, vertices, faces, s, levels, cancelled, background, shell, index, (k, n)
    )
