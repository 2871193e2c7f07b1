"""CPU volume renderer: shell bounds around the posed body, coarse-to-fine marcher with
early termination, progressive levels, and a uniform reference marcher."""
from texvocab.render.coarse import Field, Marched, coarse_pass, evaluate_field, march_until_opaque
from texvocab.render.marcher import (
    GUIDES,
    MarchSettings,
    RayResult,
    RenderCancelled,
    RenderResult,
    RenderStats,
    render_image,
    render_rays,
)
from texvocab.render.progressive import level_owners, progressive_render, progressive_shard
from texvocab.render.reference import composite_reference, mesh_bbox, ray_box, render_image_uniform
from texvocab.render.samples import RaySamples, composite, sample_pdf
from texvocab.render.shell import ShellBounds, ShellGeometry, ShellPath, shell_bounds, trace_path

__all__ = ["GUIDES", "Field", "MarchSettings", "Marched", "RayResult", "RaySamples", "RenderCancelled",
           "RenderResult", "RenderStats", "ShellBounds", "ShellGeometry", "ShellPath",
           "coarse_pass", "composite", "composite_reference", "evaluate_field", "level_owners",
           "march_until_opaque", "mesh_bbox", "progressive_render", "progressive_shard",
           "ray_box", "render_image",
           "render_image_uniform", "render_rays", "sample_pdf", "shell_bounds", "trace_path"]
