"""A moderngl context over OSMesa (Mesa's software rasteriser): no display, no EGL.

glcontext has no OSMesa backend, but ``moderngl.init_context(loader=...)`` accepts any
object with ``load_opengl_function(name) -> address``; :class:`OSMesaLoader` is that
object over libOSMesa through ctypes. The context draws into a small client-memory
buffer; all real drawing goes into framebuffer objects, so its size does not matter.

One GL platform per process (see texvocab.io.gl_platform): this coexists with PyOpenGL's
``osmesa`` platform (pyrender), which uses the same libOSMesa; it must not be mixed with
EGL or GLX contexts. pyrender makes its own context current when it renders, so code
that interleaves the two calls :func:`make_current` (or ``with ctx:``)
before drawing with moderngl.
"""

from __future__ import annotations

import ctypes
import ctypes.util

import moderngl

from texvocab.errors import TexvocabError

OSMESA_FORMAT = 0x22
OSMESA_DEPTH_BITS = 0x30
OSMESA_STENCIL_BITS = 0x31
OSMESA_ACCUM_BITS = 0x32
OSMESA_PROFILE = 0x33
OSMESA_CORE_PROFILE = 0x34
OSMESA_CONTEXT_MAJOR_VERSION = 0x36
OSMESA_CONTEXT_MINOR_VERSION = 0x37
GL_RGBA = 0x1908
GL_UNSIGNED_BYTE = 0x1401
LIBRARY_NAMES = ("libOSMesa.so.8", "libOSMesa.so.6", "libOSMesa.so")
BUFFER_SIZE = 16  # pixels per side of the (unused) default framebuffer


def load_osmesa() -> ctypes.CDLL:
    """libOSMesa with the prototypes used here; TexvocabError when it is not installed."""
    names = list(LIBRARY_NAMES)
    found = ctypes.util.find_library("OSMesa")
    if found:
        names.insert(0, found)
    for name in names:
        try:
            lib = ctypes.CDLL(name)
            break
        except OSError:
            continue
    else:
        raise TexvocabError(
            "libOSMesa not found (tried " + ", ".join(names) + "): install the "
            "Debian package libosmesa6 for headless rendering"
        )
    lib.OSMesaCreateContextAttribs.restype = ctypes.c_void_p
    lib.OSMesaCreateContextAttribs.argtypes = [ctypes.POINTER(ctypes.c_int), ctypes.c_void_p]
    lib.OSMesaMakeCurrent.restype = ctypes.c_ubyte
    lib.OSMesaMakeCurrent.argtypes = [
        ctypes.c_void_p,
        ctypes.c_void_p,
        ctypes.c_uint,
        ctypes.c_int,
        ctypes.c_int,
    ]
    lib.OSMesaGetProcAddress.restype = ctypes.c_void_p
    lib.OSMesaGetProcAddress.argtypes = [ctypes.c_char_p]
    lib.OSMesaDestroyContext.restype = None
    lib.OSMesaDestroyContext.argtypes = [ctypes.c_void_p]
    lib.OSMesaGetCurrentContext.restype = ctypes.c_void_p
    lib.OSMesaGetCurrentContext.argtypes = []
    return lib


class OSMesaLoader:
    """The loader moderngl calls: resolves GL functions, makes the context current."""

    def __init__(self, major: int = 3, minor: int = 3):
        self.lib = load_osmesa()
        attribs = [
            OSMESA_FORMAT,
            GL_RGBA,
            OSMESA_DEPTH_BITS,
            24,
            OSMESA_STENCIL_BITS,
            8,
            OSMESA_ACCUM_BITS,
            0,
            OSMESA_PROFILE,
            OSMESA_CORE_PROFILE,
            OSMESA_CONTEXT_MAJOR_VERSION,
            major,
            OSMESA_CONTEXT_MINOR_VERSION,
            minor,
            0,
        ]
        arr = (ctypes.c_int * len(attribs))(*attribs)
        self.handle = self.lib.OSMesaCreateContextAttribs(arr, None)
        if not self.handle:
            raise TexvocabError(
                f"OSMesa could not create an OpenGL {major}.{minor} core context (Mesa too old?)"
            )
        self.buffer = (ctypes.c_ubyte * (BUFFER_SIZE * BUFFER_SIZE * 4))()
        self.make_current()

    def make_current(self) -> None:
        if self.handle is None:
            raise TexvocabError("the OSMesa context was released")
        ok = self.lib.OSMesaMakeCurrent(
            self.handle, ctypes.cast(self.buffer, ctypes.c_void_p), GL_UNSIGNED_BYTE, BUFFER_SIZE, BUFFER_SIZE
        )
        if not ok:
            raise TexvocabError("OSMesaMakeCurrent failed")

    def load_opengl_function(self, name: str) -> int:
        return self.lib.OSMesaGetProcAddress(name.encode()) or 0

    def __enter__(self):
        self.make_current()

    def __exit__(self, *exc):
        pass

    def release(self) -> None:
        if self.handle is not None:
            self.lib.OSMesaDestroyContext(self.handle)
            self.handle = None


def make_current(ctx: moderngl.Context) -> None:
    """Make a context from :func:`create_headless_context` current again (after pyrender
    or another context drew on this thread)."""
    loader = (ctx.extra or {}).get("osmesa") if isinstance(ctx.extra, dict) else None
    if loader is None:
        raise TexvocabError("make_current: not a context from create_headless_context()")
    loader.make_current()


def release(ctx: moderngl.Context) -> None:
    """Release a headless context and its OSMesa context."""
    loader = ctx.extra.get("osmesa") if isinstance(ctx.extra, dict) else None
    ctx.release()
    if loader is not None:
        loader.release()


def create_headless_context() -> moderngl.Context:
    """A fresh OSMesa-backed moderngl context (OpenGL 3.3 core), current on this thread.

    The loader lives in ``ctx.extra["osmesa"]``; ``with ctx:`` or :func:`make_current`
    makes the context current again.
    """
    loader = OSMesaLoader()
    ctx = moderngl.init_context(loader=loader) or moderngl.get_context()
    ctx.extra = {"osmesa": loader}
    if ctx.version_code < 330:
        release(ctx)
        raise TexvocabError(f"OSMesa gave OpenGL {ctx.version_code}, need 3.3")
    return ctx
