"""The status line at the bottom of the window: the last error (a checkpoint that did not
open, a pose file that did not load, an export that failed) or the last thing done, where
the user looks. A long message is cut to the line's width with "..."; hovering it shows
the whole text, wrapped. An error stays until the next success replaces it, or its "x".

Widget IDs (ImGui Test Engine): the text ``StatusBar/##status``, the close button
``StatusBar/x``.
"""

from __future__ import annotations

from dataclasses import dataclass

from imgui_bundle import imgui

ERROR_COLOUR = (1.0, 0.45, 0.4, 1.0)
TOOLTIP_EM = 45.0  # the tooltip's wrap width, in font heights


@dataclass
class StatusLine:
    """``text``: the message (empty: nothing to say); ``error``: whether it is an error.
    ``drawn`` and ``tooltip``: what the line and its tooltip showed in the last frame that
    drew them (for tests)."""

    text: str = ""
    error: bool = False
    drawn: str = ""
    tooltip: str = ""

    def fail(self, text: str) -> None:
        """Show an error (until the next :meth:`done`, or its close button)."""
        self.text, self.error = text, True

    def done(self, text: str) -> None:
        """Show something that succeeded; it replaces an earlier error."""
        self.text, self.error = text, False

    def clear(self) -> None:
        self.text, self.error = "", False


def fit_text(text: str, width: float, measure) -> str:
    """The first line of ``text``, whole when it is all of ``text`` and fits in ``width``
    pixels (as ``measure(s)`` measures a string), else its longest start that fits with
    "..." after it."""
    lines = text.splitlines() or [""]
    line = lines[0]
    if len(lines) == 1 and measure(line) <= width:
        return line
    lo, hi = 0, len(line)
    while lo < hi:  # the longest prefix that fits with the ellipsis
        mid = (lo + hi + 1) // 2
        if measure(line[:mid] + "...") <= width:
            lo = mid
        else:
            hi = mid - 1
    return line[:lo] + "..."


def draw_status(status: StatusLine) -> None:
    """The status bar's contents (hello_imgui's ``callbacks.show_status``)."""
    status.drawn = ""
    if not status.text:
        return
    style = imgui.get_style()
    close = imgui.calc_text_size("x").x + 2 * style.frame_padding.x + style.item_spacing.x
    width = imgui.get_content_region_avail().x - close
    shown = fit_text(status.text, width, lambda s: imgui.calc_text_size(s).x)
    colour = imgui.ImVec4(*ERROR_COLOUR) if status.error else imgui.get_style().color_(imgui.Col_.text)
    pos = imgui.get_cursor_screen_pos()
    size = imgui.calc_text_size(shown)
    imgui.invisible_button("##status", imgui.ImVec2(max(size.x, 1.0), max(size.y, 1.0)))
    imgui.get_window_draw_list().add_text(pos, imgui.get_color_u32(colour), shown)
    status.drawn = shown
    if imgui.is_item_hovered():
        imgui.begin_tooltip()
        imgui.push_text_wrap_pos(imgui.get_font_size() * TOOLTIP_EM)
        imgui.text_unformatted(status.text)
        imgui.pop_text_wrap_pos()
        imgui.end_tooltip()
        status.tooltip = status.text
    imgui.same_line()
    if imgui.small_button("x"):
        status.clear()
