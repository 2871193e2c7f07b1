"""GLSL sources live in the repository's ``shaders/`` folder, installed as the package
``texvocab_viewer.shaders`` (a package-dir mapping in pyproject.toml); this finds and compiles them."""

from __future__ import annotations

from importlib import resources

import moderngl
import numpy as np

from texvocab.errors import TexvocabError

SHADER_DIR = resources.files("texvocab_viewer.shaders")


def shader_source(name: str) -> str:
    """The text of ``shaders/<name>``; TexvocabError naming the file when it is missing."""
    path = SHADER_DIR / name
    if not path.is_file():
        raise TexvocabError(
            f"shader file missing: {path} (the viewer's GLSL lives in {SHADER_DIR}; reinstall or restore it)"
        )
    return path.read_text(encoding="utf-8")


def build_program(ctx: moderngl.Context, vertex: str, fragment: str) -> moderngl.Program:
    """Compile ``shaders/<vertex>`` + ``shaders/<fragment>``; errors name both files."""
    try:
        return ctx.program(vertex_shader=shader_source(vertex), fragment_shader=shader_source(fragment))
    except moderngl.Error as exc:
        raise TexvocabError(f"shaders {vertex} + {fragment} do not compile: {exc}") from None


def set_uniform(prog: moderngl.Program, name: str, value) -> None:
    """Set a uniform if the compiler kept it; matrices (4, 4) are given row-major (numpy)."""
    if name not in prog:
        return
    if isinstance(value, np.ndarray) and value.shape == (4, 4):
        prog[name].write(np.ascontiguousarray(value.T, dtype="f4").tobytes())
    else:
        prog[name].value = value
