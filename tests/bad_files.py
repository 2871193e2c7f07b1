"""Damaged image files as real data has them, made in memory: a PNG that declares a huge
size over a few hundred bytes (a decompression bomb), a PNG cut short, bytes that are no
image, and a valid picture in a format captures do not use."""

import io
import struct
import zlib

import numpy as np
from PIL import Image


def _chunk(kind: bytes, data: bytes) -> bytes:
    return (
        struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    )


def png_declaring(width: int, height: int, complete: bool = False) -> bytes:
    """A well-formed 8-bit grey PNG header declaring width x height pixels, followed by one
    small IDAT of zeros: a few hundred bytes on disk whatever the size it claims. With
    ``complete``, the IDAT holds every row (zeros compress about 1000:1, so an 8000² image
    is 64 KB on disk and decodes whole)."""
    header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    if complete:
        z, row = zlib.compressobj(9), b"\0" * (width + 1)  # filter byte + pixels
        data = b"".join(z.compress(row) for _ in range(height)) + z.flush()
    else:
        data = zlib.compress(b"\0" * 65536, 9)
    return b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header) + _chunk(b"IDAT", data) + _chunk(b"IEND", b"")


def png_bytes(size: tuple[int, int] = (32, 24), seed: int = 0, mode: str = "RGB") -> bytes:
    """A valid PNG of random pixels (noise compresses badly, so a cut loses pixel data)."""
    rng = np.random.default_rng(seed)
    shape = (size[1], size[0], 3) if mode == "RGB" else (size[1], size[0])
    out = io.BytesIO()
    Image.fromarray(rng.integers(0, 256, shape, dtype=np.uint8), mode).save(out, format="PNG")
    return out.getvalue()


def truncated(data: bytes, keep: float = 0.5) -> bytes:
    """The first ``keep`` share of ``data``: a file cut short by a full disk or a copy."""
    return data[: max(1, int(len(data) * keep))]


def garbage(n: int = 4096, seed: int = 0) -> bytes:
    """Random bytes that start like no image format."""
    return b"junk" + np.random.default_rng(seed).integers(0, 256, n, dtype=np.uint8).tobytes()


def gif_bytes(size: tuple[int, int] = (16, 16)) -> bytes:
    """A valid GIF: a picture, but not a format the capture layouts use."""
    out = io.BytesIO()
    Image.new("L", size, 128).save(out, format="GIF")
    return out.getvalue()
