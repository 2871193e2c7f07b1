"""CPU volume renderer, in layers (each imports only those below it; a contract in
pyproject.toml keeps it so):

* :mod:`.progressive` — the same view coarse to fine, split over processes;
  :mod:`.reference` (a uniform marcher) and :mod:`.analytic` (fields without a network),
  for tests and benchmarks;
* :mod:`.paths` — the render paths by name (``MarchSettings.guide``) and
  :func:`render_image`;
* :mod:`.guided` — the surface-guided marcher: the surface plan, the band, the residual
  rays and the one triage of a ray that rendering and training share;
* :mod:`.shell` — the shell marcher: shell bounds around the posed body and the
  coarse-to-fine march with early termination;
* :mod:`.volume` (samples, quadrature, VolSDF's closed forms, field calls) and
  :mod:`.kernels` (compiled loops);
* :mod:`.settings` (the knobs, grouped) and :mod:`.results` (what a render returns).
"""

from texvocab.render.guided import GuidedImage, plan_surface, render_rays_banded
from texvocab.render.guided.levels import level_owners
from texvocab.render.paths import (
    GUIDES,
    RenderPath,
    prepare_shell,
    register_path,
    render_image,
    render_path,
    render_paths,
)
from texvocab.render.progressive import progressive_render, progressive_shard
from texvocab.render.reference import composite_reference, mesh_bbox, ray_box, render_image_uniform
from texvocab.render.results import RayKind, RayResult, RenderCancelled, RenderResult, RenderStats
from texvocab.render.settings import (
    MISS_REACHES,
    BandSettings,
    ChunkSettings,
    FallbackSettings,
    MarchSettings,
    ResidualSettings,
    ShellSettings,
)
from texvocab.render.shell import ShellBounds, ShellGeometry, ShellPath, shell_bounds, trace_path
from texvocab.render.shell.coarse import Marched, coarse_pass, march_until_opaque
from texvocab.render.shell.march import render_rays
from texvocab.render.volume.field import Field, evaluate_field
from texvocab.render.volume.samples import RaySamples, composite, sample_pdf

__all__ = [
    "GUIDES",
    "MISS_REACHES",
    "BandSettings",
    "ChunkSettings",
    "FallbackSettings",
    "Field",
    "GuidedImage",
    "MarchSettings",
    "Marched",
    "RayKind",
    "RayResult",
    "RaySamples",
    "RenderCancelled",
    "RenderPath",
    "RenderResult",
    "RenderStats",
    "ResidualSettings",
    "ShellBounds",
    "ShellGeometry",
    "ShellPath",
    "ShellSettings",
    "coarse_pass",
    "composite",
    "composite_reference",
    "evaluate_field",
    "level_owners",
    "march_until_opaque",
    "mesh_bbox",
    "plan_surface",
    "prepare_shell",
    "progressive_render",
    "progressive_shard",
    "ray_box",
    "register_path",
    "render_image",
    "render_image_uniform",
    "render_path",
    "render_paths",
    "render_rays",
    "render_rays_banded",
    "sample_pdf",
    "shell_bounds",
    "trace_path",
]
