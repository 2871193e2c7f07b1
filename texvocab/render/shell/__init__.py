"""The shell marcher: the δ-shell around the posed mesh (:mod:`.geometry`: bounding balls
from :mod:`.balls`, the occupancy grid), each ray's in-shell path (:mod:`.path`), the coarse
pass with scouting and early termination (:mod:`.coarse`), and the coarse-to-fine march of
rays and images (:mod:`.march`)."""

from texvocab.render.shell.geometry import ShellBounds, ShellGeometry, shell_bounds
from texvocab.render.shell.march import render_image_shell, render_rays, shell_levels
from texvocab.render.shell.path import ShellPath, trace_path

__all__ = [
    "ShellBounds",
    "ShellGeometry",
    "ShellPath",
    "render_image_shell",
    "render_rays",
    "shell_bounds",
    "shell_levels",
    "trace_path",
]
