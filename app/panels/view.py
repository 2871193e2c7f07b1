"""3D view panel: the posed body drawn by :class:`texvocab_viewer.gl.scene.SceneRenderer` into its own
framebuffer (copied into the window's, app/gl/view_blit.py), overlay toggles, and the camera:
orbit (left drag orbits, wheel zooms, right or middle drag pans), the capture's own
cameras as presets (letterboxed to their aspect; a drag leaves the preset for the nearest
orbit), a follow mode that moves the camera with the root, and Screenshot (also F12).

Widget IDs: window "3D view", checkboxes ``**/Texture``, ``**/Part colours``,
``**/Novelty``, ``**/Wireframe``, ``**/Skeleton``, ``**/Follow``, the camera combo
``**/##camera``, buttons ``**/Reset camera``, ``**/Screenshot``, the viewport
``**/##viewport``.
"""

from __future__ import annotations

from imgui_bundle import imgui

from texvocab_viewer.gl.camera import CaptureViewCamera, fit_aspect
from texvocab_viewer.gl.view_blit import ViewBlit

TOGGLES = (
    ("textured", "Texture"),
    ("part_colors", "Part colours"),
    ("novelty", "Novelty"),
    ("wireframe", "Wireframe"),
    ("skeleton", "Skeleton"),
)
ORBIT_DEG_PER_PIXEL = 0.4
ZOOM_PER_NOTCH = 0.9


def _same_line_if_fits(width: float, right: float) -> None:
    """Continue the row when an item ``width`` pixels wide ends left of ``right``
    (screen x), else start a new row."""
    imgui.same_line()
    if imgui.get_cursor_screen_pos().x + width > right:
        imgui.new_line()


def _toggles(viewer) -> None:
    o = viewer.options
    right = imgui.get_cursor_screen_pos().x + imgui.get_content_region_avail().x
    box = imgui.get_frame_height() + imgui.get_style().item_inner_spacing.x
    for i, (name, label) in enumerate(TOGGLES):
        if i:
            _same_line_if_fits(box + imgui.calc_text_size(label).x, right)
        changed, value = imgui.checkbox(label, bool(getattr(o, name)))
        if changed:
            setattr(o, name, value)
            if name == "part_colors" and value:
                o.novelty = False
            if name == "novelty" and value:
                o.part_colors = False
    _camera_row(viewer, right)


def _button_width(label: str) -> float:
    return imgui.calc_text_size(label).x + 2 * imgui.get_style().frame_padding.x


def _camera_row(viewer, right: float) -> None:
    """Camera preset combo (orbit or a capture view), Follow, Reset camera, Screenshot."""
    cap = viewer.data.capture
    names = ["orbit"] + ([f"capture view {i}" for i in range(cap.num_views)] if cap else [])
    current = viewer.camera.index + 1 if isinstance(viewer.camera, CaptureViewCamera) else 0
    imgui.set_next_item_width(150)
    changed, index = imgui.combo("##camera", current, names)
    if changed:
        viewer.set_capture_view(None if index == 0 else index - 1)
    if imgui.is_item_hovered():
        imgui.set_tooltip("camera: orbit, or one of the capture's cameras (as texvocab shot --camera N)")
    box = imgui.get_frame_height() + imgui.get_style().item_inner_spacing.x
    _same_line_if_fits(box + imgui.calc_text_size("Follow").x, right)
    changed, on = imgui.checkbox("Follow", viewer.follow)
    if changed:
        viewer.set_follow(on)
    if imgui.is_item_hovered():
        imgui.set_tooltip("the camera moves with the body's root")
    _same_line_if_fits(_button_width("Reset camera"), right)
    if imgui.button("Reset camera"):
        viewer.reset_camera()
    _same_line_if_fits(_button_width("Screenshot"), right)
    busy = viewer.export is not None and viewer.export.running
    imgui.begin_disabled(busy)
    if imgui.button("Screenshot"):
        viewer.screenshot()
    imgui.end_disabled()
    if imgui.is_item_hovered(imgui.HoveredFlags_.allow_when_disabled):
        imgui.set_tooltip("write the 3D view and the neural render of this pose under exports/ (F12)")


def _interact(viewer, height: float) -> None:
    io = imgui.get_io()
    if imgui.is_item_active():
        d = io.mouse_delta
        if d.x or d.y:
            if imgui.is_mouse_down(imgui.MouseButton_.left):
                viewer.orbit_camera().orbit(-d.x * ORBIT_DEG_PER_PIXEL, d.y * ORBIT_DEG_PER_PIXEL)
            elif imgui.is_mouse_down(imgui.MouseButton_.right) or imgui.is_mouse_down(
                imgui.MouseButton_.middle
            ):
                viewer.orbit_camera().pan(-d.x / height, d.y / height)
                if viewer.follow:
                    viewer.set_follow(True)  # keep the panned framing while following
    if imgui.is_item_hovered() and io.mouse_wheel:
        viewer.orbit_camera().zoom(ZOOM_PER_NOTCH**io.mouse_wheel)
    if imgui.is_key_pressed(imgui.Key.f12, repeat=False) and not io.want_text_input:
        viewer.screenshot()


def _legend(viewer, pos, size) -> None:
    """Novelty colour scale in the view's lower left corner."""
    draw = imgui.get_window_draw_list()
    colours = viewer.novelty_colours(9)
    x0, y1 = pos.x + 12, pos.y + size.y - 12
    w, h = 160.0, 10.0
    for i in range(len(colours) - 1):
        a = imgui.get_color_u32(imgui.ImVec4(*colours[i], 1.0))
        b = imgui.get_color_u32(imgui.ImVec4(*colours[i + 1], 1.0))
        xa = x0 + w * i / (len(colours) - 1)
        xb = x0 + w * (i + 1) / (len(colours) - 1)
        draw.add_rect_filled_multi_color(imgui.ImVec2(xa, y1 - h), imgui.ImVec2(xb, y1), a, b, b, a)
    white = imgui.get_color_u32(imgui.ImVec4(1, 1, 1, 1))
    lo, hi = viewer.novelty_range()
    draw.add_text(imgui.ImVec2(x0, y1 - h - 18), white, f"distance to nearest key: {lo:.2f} .. {hi:.2f}")


def draw_view_panel(viewer) -> None:
    """The "3D view" window's contents."""
    _toggles(viewer)
    avail = imgui.get_content_region_avail()
    w, h = int(max(avail.x, 16)), int(max(avail.y, 16))
    viewer.view_size = (w, h)
    if not viewer.framed:
        viewer.reset_camera()
        viewer.framed = True
    pos = imgui.get_cursor_screen_pos()
    size = imgui.ImVec2(w, h)
    flags = (
        imgui.ButtonFlags_.mouse_button_left
        | imgui.ButtonFlags_.mouse_button_right
        | imgui.ButtonFlags_.mouse_button_middle
    )
    imgui.invisible_button("##viewport", size, flags)
    viewer.view_rect = (pos.x, pos.y, float(w), float(h))
    _interact(viewer, float(h))
    iw, ih = w, h  # a capture camera keeps its aspect: letterboxed, centred
    if isinstance(viewer.camera, CaptureViewCamera):
        iw, ih = fit_aspect(w, h, viewer.camera.aspect)
    x0, y0 = pos.x + (w - iw) // 2, pos.y + (h - ih) // 2
    tex = viewer.render_scene((iw, ih))
    draw = imgui.get_window_draw_list()
    if tex is not None:  # copied into the window's framebuffer before the GUI is drawn
        lo, hi = draw.get_clip_rect_min(), draw.get_clip_rect_max()
        viewer.view_blit = ViewBlit(viewer.scene.fbo.glo, x0, y0, iw, ih, (lo.x, lo.y, hi.x, hi.y))
    grey = imgui.get_color_u32(imgui.ImVec4(0.85, 0.85, 0.85, 1.0))
    draw.add_text(imgui.ImVec2(pos.x + 8, pos.y + 6), grey, viewer.view_caption())
    if viewer.options.novelty:
        _legend(viewer, pos, size)
