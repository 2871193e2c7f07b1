"""The one reader of a capture's images and masks: every image and mask any layout lists is
opened here, so a damaged file is always one :class:`~texvocab.errors.AssetError` naming it.

* Only PNG and JPEG files are read (the layouts' formats); anything else is refused by name.
* The pixel count is read from the header and checked against :data:`MAX_PIXELS` before any
  pixel is decoded: a small file that declares a huge image (a decompression bomb) never
  allocates its pixels. PIL's own bomb guard (``Image.MAX_IMAGE_PIXELS``) is left as the
  process has it; its error and warning are turned into the same one line.
* A decode error or a truncated file (PIL reads it lazily, so it shows while decoding) names
  the file and PIL's reason.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from PIL import Image

from texvocab.errors import AssetError

#: Most pixels a capture image or mask may have (an 8K UHD frame, 7680x4320, has 33 M); its
#: float32 RGB copy is then at most 480 MB.
MAX_PIXELS = 40_000_000
#: The formats capture layouts use (PIL's JPEG reader also opens MPO, the JPEG phones write).
FORMATS = ("PNG", "JPEG")
_PIL_BOMB = re.compile(r"\((\d+) pixels\)")


def _over_limit(path: Path, what: str, pixels: int, size: str) -> AssetError:
    return AssetError(
        f"{path}: {what} of {size}{pixels / 1e6:.0f} Mpx is over the limit of "
        f"{MAX_PIXELS / 1e6:.0f} Mpx for a capture image; refused before decoding"
    )


@contextmanager
def _opened(path: Path, what: str) -> Iterator[Image.Image]:
    """The PIL image of ``path`` with only its header read, its format and size checked."""
    path = Path(path)
    if not path.is_file():
        raise AssetError(f"{path}: {what} not found")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            im = Image.open(path, formats=FORMATS)
    except (Image.DecompressionBombError, Image.DecompressionBombWarning) as exc:
        found = _PIL_BOMB.search(str(exc))
        raise _over_limit(path, what, int(found.group(1)) if found else 10**10, "") from None
    except Exception as exc:  # noqa: BLE001 -- any failure of the header parser is a bad file
        raise AssetError(
            f"{path}: not a readable {what} ({type(exc).__name__}: {exc}); expected a PNG or JPEG file"
        ) from None
    with im:
        w, h = im.size
        if w < 1 or h < 1 or w * h > MAX_PIXELS:
            raise _over_limit(path, what, w * h, f"{w}x{h} pixels, ")
        yield im


def image_size(path: Path, what: str = "image") -> tuple[int, int]:
    """(width, height) from the header of a capture image or mask (no pixel decoded)."""
    with _opened(path, what) as im:
        return im.size


def first_size(paths: list[Path], what: str = "image") -> tuple[int, int]:
    """(width, height) of the first of ``paths`` whose header reads (a view's size when its
    first file is damaged: the image checks name that one); the first error when none do."""
    first_error = None
    for path in paths:
        try:
            return image_size(path, what)
        except AssetError as e:
            first_error = first_error or e
    raise first_error or AssetError(f"no {what} to read a size from")


def _decoded(path: Path, mode: str, what: str) -> np.ndarray:
    """uint8 pixels of ``path`` converted to ``mode`` ("RGB" (H, W, 3) or "L" (H, W))."""
    with _opened(path, what) as im:
        try:
            im.load()
            out = np.asarray(im.convert(mode), dtype=np.uint8)
        except Exception as exc:  # noqa: BLE001 -- a decoder failure: truncated or damaged data
            raise AssetError(
                f"{path}: not a readable {what}: {type(exc).__name__}: {exc} (truncated or "
                "damaged); expected a whole PNG or JPEG file"
            ) from None
    return out


def read_image(path: Path) -> np.ndarray:
    """(H, W, 3) float32 RGB in [0, 1] of a capture image."""
    return _decoded(path, "RGB", "image").astype(np.float32) / np.float32(255.0)


def read_mask(path: Path) -> np.ndarray:
    """(H, W) bool: foreground where the (possibly JPEG-compressed) mask is > 127."""
    return _decoded(path, "L", "mask") > 127


def verify_image(path: Path, what: str = "image") -> None:
    """Decode ``path`` fully and drop the pixels: AssetError when it is damaged."""
    _decoded(path, "RGB" if what == "image" else "L", what)
