"""The guided marcher's progressive levels (:mod:`texvocab.render.progressive`): a level is
every ``level``-th pixel of the full image in both directions. The first of several levels
is a preview with a plan of its own; after it, each level renders only the pixels the
coarser ones have not: those levels together cost one full-resolution render (its plan,
the rasterisation, is made once), and the last level *is* that render. Shards split each
level's new pixels round-robin in row-major order (:func:`level_owners`)."""

from __future__ import annotations

import time
from collections.abc import Iterator

import torch

from texvocab.render.guided.image import GuidedImage
from texvocab.render.results import RenderCancelled
from texvocab.render.settings import MarchSettings


def level_owners(height: int, width: int, levels=(8, 4, 2, 1), shards: int = 1) -> Iterator[torch.Tensor]:
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


def guided_levels(
    field,
    camera,
    vertices,
    faces,
    s: MarchSettings,
    levels,
    cancelled,
    background,
    shell,
    index=None,
    shard=(0, 1),
) -> Iterator[tuple[int, torch.Tensor, float, torch.Tensor]]:
    """The guided marcher's levels as shard ``shard = (k, n)`` renders them: ``(level,
    image (H_l, W_l, 3), seconds, owned (H_l, W_l) bool)``. The first of several levels is
    a preview of its own: the camera of every ``level``-th pixel (``Camera.every``: the
    same rays as ``image[::level, ::level]``) with its own small plan, and rays that would
    be residual or marched rays shown with their probe's colour. So the first image needs
    neither the full image's plan nor any shell geometry (``shell`` may be a function that
    builds it); the next level renders those pixels again with the rest (1/64 more rays
    at levels 8, 4, 2, 1)."""
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
                    rgb = _preview(
                        field,
                        camera.every(level),
                        vertices,
                        faces,
                        s,
                        background,
                        shell,
                        index,
                        cancelled,
                        k == 0,
                    )
                else:
                    if image is None:
                        image = GuidedImage(field, camera, vertices, faces, s, background, shell, index)
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


def _preview(
    field, camera, vertices, faces, s, background, shell, index, cancelled, render: bool
) -> torch.Tensor:
    """The image (H, W, 3) of ``camera`` with the rays the band leaves at their probe's
    colour (the background when not ``render``: another shard's preview)."""
    if not render:
        return torch.as_tensor(background, dtype=torch.float32).expand(camera.height, camera.width, 3).clone()
    small = GuidedImage(field, camera, vertices, faces, s, background, shell, index)
    small.render(None, cancelled, preview=True)
    return small.rgb.view(camera.height, camera.width, 3).clone()
