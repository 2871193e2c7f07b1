"""Waking the idling window from another thread when a render level arrives.

The window idles at 1 frame per second (app/window.py) and must draw a frame as soon as
a level arrives. ``hello_imgui.request_refresh`` does that and also makes the following
frame come at full speed; an empty GLFW event (``glfwPostEmptyEvent``, thread-safe) only
ends the window's wait, so one frame is drawn and the window idles again. Measured with
bench/viewer_ui.py (render process, 256x132, 4 renders each): 6-8 UI frames per render and
0.62-0.71 of a core outside the render with the refresh, 4-5 frames and 0.55-0.62 with
the empty event. GLFW here is the library imgui_bundle's extension is linked against (the
same shared object, so the same initialised instance); without it the refresh is used.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from pathlib import Path

import imgui_bundle
from imgui_bundle import hello_imgui


def _glfw_library():
    """The libglfw imgui_bundle's extension is linked against, or None."""
    folder = Path(imgui_bundle.__file__).parent
    for name in ("libglfw.so.3", "libglfw.so", "libglfw.3.dylib", "libglfw.dylib", "glfw3.dll"):
        if (folder / name).is_file():
            try:
                return ctypes.CDLL(str(folder / name))
            except OSError:
                return None
    return None


def ui_waker() -> Callable[[], None]:
    """A function any thread may call to have the window draw one frame soon."""
    lib = _glfw_library()
    post = None if lib is None else getattr(lib, "glfwPostEmptyEvent", None)
    if post is None:
        return hello_imgui.request_refresh
    post.restype, post.argtypes = None, []
    return post
