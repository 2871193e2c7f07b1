"""The 3D view's copy into the window (app/gl/view_blit.py): which rows and columns of the
scene's framebuffer land where in the window's, GL rows counted from the bottom. The copy
itself runs in the window tests (tests/app/test_app_window.py: the body in the screenshot's
3D view)."""

from __future__ import annotations

from texvocab_viewer.gl.view_blit import ViewBlit, blit_rects

FB = (1280, 800)


def test_the_whole_view_lands_one_to_one_rows_flipped_to_gl():
    b = ViewBlit(7, 300.0, 100.0, 500, 600, (290.0, 90.0, 900.0, 790.0))
    src, dst = blit_rects(b, FB)
    assert src == (0, 0, 500, 600)
    # ImGui's rows from the top: 100..700 -> GL rows from the bottom: 800-700 .. 800-100
    assert dst == (300, 100, 800, 700)


def test_a_clipped_view_copies_only_its_visible_part():
    # the panel's clip cuts 50 pixels off the view's top and 20 off its right
    b = ViewBlit(7, 300.0, 100.0, 500, 600, (300.0, 150.0, 780.0, 790.0))
    src, dst = blit_rects(b, FB)
    assert src == (0, 0, 480, 550)  # the image's top 50 rows are its GL rows 550..600
    assert dst == (300, 100, 780, 650)
    assert src[2] - src[0] == dst[2] - dst[0] and src[3] - src[1] == dst[3] - dst[1]


def test_a_hidpi_framebuffer_scales_the_destination():
    b = ViewBlit(7, 10.0, 20.0, 100, 50, (0.0, 0.0, 640.0, 400.0))
    src, dst = blit_rects(b, FB, scale=(2.0, 2.0))
    assert src == (0, 0, 100, 50)
    assert dst == (20, 800 - 140, 220, 800 - 40)


def test_nothing_is_copied_when_the_view_is_clipped_away_or_off_screen():
    assert blit_rects(ViewBlit(7, 300.0, 100.0, 500, 600, (0.0, 0.0, 200.0, 800.0)), FB) is None
    assert blit_rects(ViewBlit(7, 1300.0, 100.0, 50, 60, (0.0, 0.0, 2000.0, 800.0)), FB) is None
