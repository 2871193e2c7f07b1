"""Contact sheets: tiles in a grid, and labels that draw the settings' characters."""

import numpy as np

from texvocab.io.images import contact_sheet, label_font


def _ink(text: str) -> np.ndarray:
    """The label's pixels as contact_sheet draws a column label (True: dark)."""
    sheet = contact_sheet([[np.ones((8, 200, 3))]], col_labels=[text])
    return sheet[:16].min(-1) < 128


def test_tiles_and_labels_are_placed():
    a, b = np.zeros((10, 12, 3)), np.ones((10, 12))
    sheet = contact_sheet([[a, b]], row_labels=["row"], col_labels=["one", "two"])
    assert sheet.shape == (16 + 10 + 2 * 4, 90 + 2 * (12 + 4) + 4, 3) and sheet.dtype == np.uint8
    assert (sheet[20:30, 94:106] == 0).all() and (sheet[20:30, 110:122] == 255).all()
    assert _ink("one").any() and not _ink("").any()


def test_greek_letters_and_subscripts_are_drawn_not_boxed():
    """β₀, λ and δ (the ablations' labels) each draw their own glyph: a box (the
    missing-glyph mark) would be the same picture for all of them."""
    font = label_font()
    assert hasattr(font, "getname") and font.getname()[0] == "DejaVu Sans"
    shapes = [_ink(c) for c in ("β", "λ", "δ", "₀", "\ue000")]
    for i in range(len(shapes)):
        assert shapes[i].any()
        for j in range(i + 1, len(shapes)):
            assert not np.array_equal(shapes[i], shapes[j]), (i, j)
