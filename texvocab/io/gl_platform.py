"""Pick PyOpenGL's offscreen platform once per process, before OpenGL is imported.

PyOpenGL binds its platform (osmesa / egl / glx) at first import and cannot change it;
mixing OSMesa with EGL/GLX contexts in one process gives wrong pixels (the
second platform's reads come back black or stale). Call :func:`ensure_offscreen` before importing pyrender.
"""

from __future__ import annotations

import os
import sys

OFFSCREEN_PLATFORMS = ("osmesa", "egl")


def ensure_offscreen(default: str = "osmesa") -> str:
    """Set PYOPENGL_PLATFORM to ``default`` unless the user chose one; return the choice.

    Raises RuntimeError when OpenGL was already imported under a different platform.
    """
    chosen = os.environ.setdefault("PYOPENGL_PLATFORM", default)
    if "OpenGL" in sys.modules:
        # late: only once OpenGL is loaded; importing it here would bind its platform
        import OpenGL.platform as glp  # noqa: PLC0415

        bound = type(glp.PLATFORM).__name__.lower()
        if chosen not in bound:
            raise RuntimeError(
                f"OpenGL is already bound to {bound}; PYOPENGL_PLATFORM={chosen} "
                "must be set before anything imports OpenGL"
            )
    return chosen
