"""Neural render panel: the trained avatar rendered by the CPU ray marcher
(:class:`texvocab_viewer.neural.view.NeuralView`) from the 3D view's camera, coarse to fine
(1/8 .. 1), with the level shown and how long it took. A stale image (the pose, camera or
size changed since) is dimmed under a banner that says why ("stale, pose edited since:
shows ...", cut to the image's width); hovering the image shows the banner's whole text,
the pose shown and the pose now. Without a checkpoint it says why it is empty.

Widget IDs: window "Neural render", ``**/Live``, ``**/resolution``, ``**/Render now``,
``**/preset``, the image's room ``**/##image``.
"""

from __future__ import annotations

from imgui_bundle import imgui

from texvocab.pipeline import RENDER_PRESETS as PRESETS
from texvocab_viewer.neural.worker import RenderFrame
from texvocab_viewer.status import fit_text

STALE_TINT = (0.45, 0.45, 0.45, 1.0)
BANNER_PAD = 6.0  # pixels left and right of the banner's text


def banner_text(reason: str, line: str, width: float, measure) -> str:
    """The stale banner for an image ``width`` pixels wide: "stale, REASON: DETAIL" (the
    detail is ``line``, :meth:`NeuralView.stale_line`, after its "stale: "), or, when that
    does not fit, "stale, REASON" (cut with "..." if even that is too long); "" when the
    image is current. ``measure(s)``: the width of ``s`` in pixels."""
    if not line:
        return ""
    room = width - 2 * BANNER_PAD
    full = f"stale, {reason}: {line.removeprefix('stale: ')}"
    if measure(full) <= room:
        return full
    return fit_text(f"stale, {reason}", room, measure)


def status_line(
    frame: RenderFrame | None, busy: bool, playback_level: int | None = None, stale: bool = False
) -> str:
    """What the shown image is and how long it took; during playback, the level the render
    follows the timeline at."""
    if frame is None:
        return "rendering..." if busy else "waiting"
    level = "full resolution" if frame.level == 1 else f"1/{frame.level} resolution"
    h, w = frame.image.shape[:2]
    if playback_level is not None:
        nxt = "full" if playback_level == 1 else f"1/{playback_level}"
        return (
            f"playback: {level} ({w}x{h}) in {frame.elapsed:.2f} s per frame; following "
            f"the timeline at {nxt} resolution"
        )
    if stale:
        return f"shown: {level} ({w}x{h}) of the previous view; rendering the new one..."
    total = f"{frame.elapsed:.1f} s so far, refining..." if busy else f"{frame.elapsed:.1f} s in all"
    return f"{level} ({w}x{h}): {frame.seconds * 1000:.0f} ms; {total}"


def draw_neural_panel(viewer) -> None:
    """The "Neural render" window's widgets; its status and image follow in
    :func:`late_draw`."""
    nv = viewer.neural
    if nv is None:
        imgui.push_text_wrap_pos(0.0)
        imgui.text_disabled(viewer.neural_absent_reason())
        imgui.pop_text_wrap_pos()
        return
    _, nv.live = imgui.checkbox("Live", nv.live)
    if imgui.is_item_hovered():
        imgui.set_tooltip("re-render whenever the pose or the camera changes")
    imgui.same_line()
    imgui.set_next_item_width(120)
    _, nv.resolution = imgui.slider_int("resolution", nv.resolution, 64, 512, "%d px")
    imgui.same_line()
    force = imgui.button("Render now")
    names = ["checkpoint", *PRESETS]
    imgui.set_next_item_width(120)
    changed, index = imgui.combo("preset", names.index(nv.preset), names)
    if changed:
        nv.set_preset(names[index])
    if imgui.is_item_hovered():
        imgui.set_tooltip("speed/accuracy preset of the render knobs (bench/tradeoff.py)")
    playing = viewer.sequence is not None and viewer.sequence.playing
    viewer.submit_neural(force)  # also done before the panels draw (Viewer.pre_new_frame)
    # the status lines and the image are drawn by late_draw, after the frame's last poll
    # (NeuralView.late_poll): a level that arrives while this frame is built is in it
    line = imgui.get_text_line_height()
    canvas = {
        "draw": imgui.get_window_draw_list(),
        "status": imgui.get_cursor_screen_pos(),
        "playing": playing,
    }
    imgui.dummy(imgui.ImVec2(1.0, line))
    if playing:
        canvas["playback"] = imgui.get_cursor_screen_pos()
        imgui.dummy(imgui.ImVec2(1.0, line))
    for err in list(nv.worker.errors)[-1:]:
        imgui.text_colored(imgui.ImVec4(1.0, 0.45, 0.4, 1.0), err)
    avail = imgui.get_content_region_avail()
    canvas["image"] = (imgui.get_cursor_screen_pos(), avail)
    imgui.invisible_button("##image", imgui.ImVec2(max(avail.x, 1.0), max(avail.y, 1.0)))  # its room
    canvas["hovered"] = imgui.is_item_hovered()
    d = canvas["draw"]
    canvas["clip"] = (d.get_clip_rect_min(), d.get_clip_rect_max())
    nv.canvas = canvas


def late_draw(viewer) -> None:
    """Draw what the Neural render panel left room for (status lines, the image, the stale
    banner) into its window, once :meth:`NeuralView.late_poll` took the frame's newest
    level. A stale image (pose or camera changed since) is dimmed and labelled with the
    pose it shows until the first new level replaces it."""
    nv = viewer.neural
    if nv is None or nv.canvas is None:
        return
    canvas, nv.canvas = nv.canvas, None
    nv.image_rect = None
    draw, playing = canvas["draw"], canvas["playing"]
    text = imgui.get_color_u32(imgui.Col_.text)
    draw.push_clip_rect(*canvas["clip"])
    try:
        draw.add_text(
            canvas["status"],
            text,
            status_line(nv.frame, nv.busy, nv.playback_level if playing else None, nv.stale),
        )
        if "playback" in canvas and nv.frame is not None:
            draw.add_text(
                canvas["playback"],
                imgui.get_color_u32(imgui.Col_.text_disabled),
                f"shows {nv.labels.get(nv.frame.version, 'an earlier frame')}; "
                f"the timeline is at {viewer.pose_label()}",
            )
        line = "" if playing else nv.stale_line()
        banner = ""
        if nv.texture is not None:
            nv.image_rect, banner = _draw_image(draw, nv, *canvas["image"], line)
            nv.on_screen = nv.frame
    finally:
        draw.pop_clip_rect()
    tooltip = nv.stale_tooltip() if banner and canvas.get("hovered") else ""
    if tooltip:
        imgui.set_tooltip(tooltip)
    viewer.neural_stale_shown = nv.stale_line()
    viewer.neural_banner_drawn, viewer.neural_tooltip = banner, tooltip
    viewer.stale_log.append(viewer.neural_stale_shown)


def _draw_image(draw, nv, pos, avail, line: str) -> tuple[tuple[float, float, float, float], str]:
    """The shown level scaled into ``avail`` at ``pos``, dimmed under the stale banner
    when ``line`` (:meth:`NeuralView.stale_line`) says it is stale; its rectangle (x0, y0,
    x1, y1) and the banner drawn ("" for none)."""
    tw, th = nv.texture.size
    scale = min(avail.x / tw, avail.y / th) if avail.x > 0 and avail.y > 0 else 1.0
    end = imgui.ImVec2(pos.x + tw * scale, pos.y + th * scale)
    tint = imgui.get_color_u32(imgui.ImVec4(*(STALE_TINT if nv.stale else (1, 1, 1, 1))))
    draw.add_image(imgui.ImTextureRef(nv.texture.glo), pos, end, imgui.ImVec2(0, 0), imgui.ImVec2(1, 1), tint)
    banner = banner_text(nv.stale_reason(), line, end.x - pos.x, lambda s: imgui.calc_text_size(s).x)
    if banner:  # within the image, which a preview drawn before the swap covers wholly
        draw.push_clip_rect(pos, end, True)
        draw.add_rect_filled(
            pos, imgui.ImVec2(end.x, pos.y + 22), imgui.get_color_u32(imgui.ImVec4(0.0, 0.0, 0.0, 0.6))
        )
        draw.add_text(
            imgui.ImVec2(pos.x + BANNER_PAD, pos.y + 4),
            imgui.get_color_u32(imgui.ImVec4(1.0, 0.8, 0.3, 1.0)),
            banner,
        )
        draw.pop_clip_rect()
    return (pos.x, pos.y, end.x, end.y), banner
