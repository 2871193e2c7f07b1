"""The 3D view's image copied straight into the window's framebuffer.

The panel (app/panels/view.py) leaves the view's rectangle empty and says where it is
(:class:`ViewBlit`); just before ImGui draws the frame (``Viewer.before_imgui_render``),
the scene's framebuffer is copied there with ``glBlitFramebuffer``, one to one, and the
GUI (caption, legend, popups) is drawn over it. Under Mesa llvmpipe this is a copy, where
ImGui's textured, alpha-blended quad over the same pixels cost about 2 ms of rasterisation
in every frame (bench/viewer_ui.py; a 520x700 view of a 1280x800 window).

The neural render's preview is drawn the same way, scaled (:func:`image_rects`,
:func:`blit_image`), over the frame ImGui drew, just before the swap
(``Viewer.before_swap``).

PyOpenGL is imported at the first copy, once the window has chosen its platform
(texvocab_viewer.window._choose_gl_platform).
"""

from __future__ import annotations

from dataclasses import dataclass

from imgui_bundle import imgui


@dataclass
class ViewBlit:
    """Where the 3D view goes this frame, in ImGui's coordinates (pixels from the window's
    top left): the image's rectangle x, y, w, h and the panel's clip rectangle."""

    fbo: int  # GL name of the scene's framebuffer, w x h
    x: float
    y: float
    w: int
    h: int
    clip: tuple[float, float, float, float]  # x0, y0, x1, y1


def blit_rects(blit: ViewBlit, framebuffer_size: tuple[int, int], scale: tuple[float, float] = (1.0, 1.0)):
    """(src, dst) rectangles (x0, y0, x1, y1) of ``glBlitFramebuffer``, rows counted from
    the bottom in both framebuffers, for the part of ``blit``'s image inside its clip
    rectangle; None when none of it is in the window. ``scale``: ImGui's display
    framebuffer scale (window pixels per ImGui unit)."""
    sx, sy = scale
    fw, fh = framebuffer_size
    x0, y0 = max(blit.x, blit.clip[0]), max(blit.y, blit.clip[1])
    x1 = min(blit.x + blit.w, blit.clip[2])
    y1 = min(blit.y + blit.h, blit.clip[3])
    # the visible part in the scene image's pixels (rows counted from its top)
    left, top = round(x0 - blit.x), round(y0 - blit.y)
    right, bottom = round(x1 - blit.x), round(y1 - blit.y)
    if right <= left or bottom <= top:
        return None
    src = (left, blit.h - bottom, right, blit.h - top)
    dst = (
        round((blit.x + left) * sx),
        round(fh - (blit.y + bottom) * sy),
        round((blit.x + right) * sx),
        round(fh - (blit.y + top) * sy),
    )
    if dst[2] <= 0 or dst[3] <= 0 or dst[0] >= fw or dst[1] >= fh:
        return None
    return src, dst


def blit_view(
    blit: ViewBlit, framebuffer_size: tuple[int, int], scale: tuple[float, float] = (1.0, 1.0)
) -> bool:
    """Copy the scene's framebuffer into the window's (GL framebuffer 0) at ``blit``'s
    rectangle (:func:`blit_rects`). False when nothing of it is visible."""
    rects = blit_rects(blit, framebuffer_size, scale)
    if rects is None:
        return False
    blit_image(blit.fbo, rects, linear=tuple(scale) != (1.0, 1.0))
    return True


def image_rects(
    rect: tuple[float, float, float, float],
    texture_size: tuple[int, int],
    framebuffer_size: tuple[int, int],
    scale: tuple[float, float] = (1.0, 1.0),
):
    """(src, dst) rectangles of ``glBlitFramebuffer`` that draw a whole texture (w, h) whose
    row 0 is the image's top (as the neural render's levels are uploaded) into ``rect``
    (x0, y0, x1, y1 in ImGui's coordinates); None when the rectangle is empty or not
    wholly inside the window."""
    sx, sy = scale
    fw, fh = framebuffer_size
    x0, y0 = round(rect[0] * sx), round(fh - rect[1] * sy)  # the image's top edge
    x1, y1 = round(rect[2] * sx), round(fh - rect[3] * sy)  # its bottom edge
    if x1 <= x0 or y0 <= y1 or x0 < 0 or y1 < 0 or x1 > fw or y0 > fh:
        return None
    tw, th = texture_size
    return (0, 0, tw, th), (x0, y0, x1, y1)  # texture row 0 to the top: flipped


def blit_image(fbo: int, rects, linear: bool = True) -> None:
    """Copy the (src, dst) ``rects`` (:func:`blit_rects`, :func:`image_rects`) of
    framebuffer ``fbo`` into the window's (GL framebuffer 0), filtered linearly or not."""
    from OpenGL import GL  # late: after the window chose PyOpenGL's platform

    GL.glDisable(GL.GL_SCISSOR_TEST)
    GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, fbo)
    GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, 0)
    GL.glBlitFramebuffer(
        *rects[0], *rects[1], GL.GL_COLOR_BUFFER_BIT, GL.GL_LINEAR if linear else GL.GL_NEAREST
    )
    GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)


def warm_image_blit(ctx, colour: tuple[float, float, float]) -> None:
    """Blits as ``Viewer.before_swap`` draws a preview (an RGB texture, scaled, flipped,
    linear) of ``colour`` (the window's background) onto 2x3 pixels of the window's
    bottom-left corner, from textures whose sides are and are not powers of two (Mesa
    llvmpipe compiles a sampler per combination): called in the first frame, so that code
    is compiled there (the first blit of a preview took 30-40 ms, later ones 1.3 ms), not
    in a pose's frame. ``ctx``: the window's moderngl context."""
    texel = bytes(round(255 * max(0.0, min(1.0, c))) for c in colour)
    for w, h in ((4, 4), (4, 3), (3, 4), (3, 3)):
        texture = ctx.texture((w, h), 3, texel * (w * h), alignment=1)
        fbo = ctx.framebuffer(color_attachments=[texture])
        blit_image(fbo.glo, ((0, 0, w, h), (0, 3, 2, 0)))
        fbo.release()
        texture.release()
    ctx.screen.use()


def gl_flush() -> None:
    """Have GL start on the commands issued so far (``glFlush``) without waiting for them."""
    from OpenGL import GL  # late: after the window chose PyOpenGL's platform

    GL.glFlush()


def window_framebuffer() -> tuple[tuple[int, int], tuple[float, float]]:
    """(the window's framebuffer size in pixels, ImGui's display framebuffer scale)."""
    io = imgui.get_io()
    scale = (io.display_framebuffer_scale.x, io.display_framebuffer_scale.y)
    return (round(io.display_size.x * scale[0]), round(io.display_size.y * scale[1])), scale
