"""PNG writing (atomic) and contact sheets."""

from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from texvocab.io.full_disk import disk_full_cause
from texvocab.io.stop_flag import raise_if_stopped
from texvocab.io.temp_files import sweep_stale, temp_file


def to_uint8(image: np.ndarray) -> np.ndarray:
    """float [0, 1] (H, W[, C]) -> uint8; uint8 passes through."""
    if image.dtype == np.uint8:
        return image
    return (np.clip(image, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def _umask() -> int:
    """The process's umask, read without changing it (Linux: /proc), else set and restored."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except OSError:
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def atomic_write_bytes(path: str | Path, write) -> Path:
    """Call ``write(tmp_path)`` then rename onto ``path``: never a half-written file. The
    temporary file is named for this process (:mod:`texvocab.io.temp_files`), removed on
    any error or interrupt; the first write into a folder sweeps the temporary files of
    writers that were killed. A full disk is raised as an OSError naming ``path``
    (:mod:`texvocab.io.full_disk`)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    sweep_stale(path.parent)
    tmp = temp_file(path)
    os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes it 0600; the file gets the user's umask
    try:
        write(tmp)
        raise_if_stopped()  # a stop signal that a library swallowed (texvocab.io.stop_flag)
        os.replace(tmp, path)
    except BaseException as e:
        Path(tmp).unlink(missing_ok=True)
        full = disk_full_cause(e)
        if full is not None:  # a file object's write names no file: say which one
            raise OSError(full.errno, full.strerror, str(path)) from e
        raise
    return path


def save_png(path: str | Path, image: np.ndarray) -> Path:
    """Write an RGB/grey image (float [0, 1] or uint8) as PNG, atomically."""
    img = Image.fromarray(to_uint8(image))
    return atomic_write_bytes(path, lambda tmp: img.save(tmp, format="PNG"))


@functools.cache
def label_font(size: int = 11) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    """The labels' font: DejaVu Sans where the system has it (Greek letters, subscripts
    and the other characters of the settings' names: β₀, λ_m, δ), else Pillow's default,
    whose glyphs stop at Latin letters (other characters are drawn as boxes)."""
    try:
        return ImageFont.truetype("DejaVuSans.ttf", size)
    except OSError:
        return ImageFont.load_default()


def contact_sheet(
    rows: list[list[np.ndarray]], row_labels=None, col_labels=None, pad: int = 4, label_h: int = 16
) -> np.ndarray:
    """Grid of equally sized images with optional labels; returns uint8 (H, W, 3)."""
    h, w = rows[0][0].shape[:2]
    n_rows, n_cols = len(rows), max(len(r) for r in rows)
    left = 90 if row_labels else 0
    top = label_h if col_labels else 0
    sheet = Image.new(
        "RGB", (left + n_cols * (w + pad) + pad, top + n_rows * (h + pad) + pad), (255, 255, 255)
    )
    draw = ImageDraw.Draw(sheet)
    for r, row in enumerate(rows):
        y = top + pad + r * (h + pad)
        if row_labels:
            draw.text((4, y + h // 2), row_labels[r], fill=(0, 0, 0), font=label_font())
        for c, img in enumerate(row):
            x = left + pad + c * (w + pad)
            tile = to_uint8(img)
            tile = np.repeat(tile[..., None], 3, -1) if tile.ndim == 2 else tile[..., :3]
            sheet.paste(Image.fromarray(tile), (x, y))
    if col_labels:
        for c, label in enumerate(col_labels):
            draw.text((left + pad + c * (w + pad) + 4, 2), label, fill=(0, 0, 0), font=label_font())
    return np.asarray(sheet)
