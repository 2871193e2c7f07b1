"""The render paths by name: ``MarchSettings.guide`` picks one, and everything that renders
an image (:func:`render_image`, the progressive levels, a caller preparing the per-pose
shell) asks the registry instead of testing the name. Built in: "shell" (the shell marcher,
:mod:`texvocab.render.shell`) and "raster" (the surface-guided marcher,
:mod:`texvocab.render.guided`); a new path is one :func:`register_path` call.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import torch

from texvocab.render.guided.image import render_image_guided
from texvocab.render.guided.levels import guided_levels
from texvocab.render.results import RenderResult
from texvocab.render.settings import MarchSettings
from texvocab.render.shell.geometry import ShellGeometry
from texvocab.render.shell.march import build_shell, render_image_shell, shell_levels
from texvocab.render.volume.field import Field


@dataclass(frozen=True)
class RenderPath:
    """One way to render an image.

    render: ``(field, camera, vertices, faces, settings, background, shell, generator,
        cancelled, index) -> RenderResult`` (:func:`render_image`'s arguments).
    levels: ``(field, camera, vertices, faces, settings, levels, cancelled, background,
        shell, index, shard) -> iterator of (level, image, seconds, owned)``, the
        progressive levels a shard renders (:func:`texvocab.render.progressive_shard`).
    wants_shell: the path marches every ray through the shell grid, so a caller that
        renders several images of a pose builds the shell once beforehand
        (:func:`prepare_shell`); False: the path builds what it needs of the shell itself.
    """

    name: str
    render: Callable[..., RenderResult]
    levels: Callable[..., Iterator[tuple[int, torch.Tensor, float, torch.Tensor]]]
    wants_shell: bool


_PATHS: dict[str, RenderPath] = {}


def register_path(path: RenderPath) -> None:
    """Make ``path`` available as ``MarchSettings(guide=path.name)`` (a name is taken once)."""
    if path.name in _PATHS:
        raise ValueError(f"render path {path.name!r} is registered already")
    _PATHS[path.name] = path


def render_paths() -> tuple[str, ...]:
    """The registered paths' names, sorted."""
    return tuple(sorted(_PATHS))


def render_path(name: str) -> RenderPath:
    """The registered path called ``name``; ValueError naming the known ones otherwise."""
    if name not in _PATHS:
        raise ValueError(f"MarchSettings.guide={name!r}: expected one of {render_paths()}")
    return _PATHS[name]


register_path(RenderPath("shell", render_image_shell, shell_levels, wants_shell=True))
register_path(RenderPath("raster", render_image_guided, guided_levels, wants_shell=False))

#: the built-in paths' names (the pipeline's settings check ``guide`` against them)
GUIDES = render_paths()


def render_image(
    field: Field,
    camera,
    vertices,
    faces,
    settings: MarchSettings | None = None,
    background=(0.0, 0.0, 0.0),
    shell: ShellGeometry | None = None,
    generator: torch.Generator | None = None,
    cancelled: Callable[[], bool] | None = None,
    index=None,
) -> RenderResult:
    """Render one image of the field around the posed mesh (vertices (V, 3), faces (F, 3))
    by the path ``settings.guide`` names.

    Pass a prebuilt ``shell`` (:meth:`ShellGeometry.build` of the same mesh) to reuse the
    per-pose work across images; it then overrides the shell group's width and voxel.
    ``cancelled`` is checked between ray chunks; when it returns True,
    :class:`~texvocab.render.results.RenderCancelled` is raised. ``index``: the mesh's
    SurfaceIndex, which the surface-guided marcher uses for its residual rays (built when
    needed if not given). ``generator``: random samples for the shell marcher (None:
    deterministic). The shell marcher is differentiable w.r.t. the field's outputs.
    """
    s = settings or MarchSettings()
    return render_path(s.guide).render(
        field, camera, vertices, faces, s, background, shell, generator, cancelled, index
    )


def prepare_shell(settings: MarchSettings, vertices, faces, index=None) -> ShellGeometry | None:
    """The shell to build once per pose for the path ``settings.guide`` names
    (:attr:`RenderPath.wants_shell`), None when the path builds what it needs itself.
    ``index``: the mesh's SurfaceIndex for the grid's exact distances (built if not given)."""
    if not render_path(settings.guide).wants_shell:
        return None
    return build_shell(settings, vertices, faces, index)
