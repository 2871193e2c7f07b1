"""A stand-in for clothes off the body: a capture whose masks are dilated beyond the body."""

from scipy import ndimage

from texvocab.capture import open as open_capture


def grown(root, pixels: int):
    """The capture at ``root`` with every mask dilated by ``pixels`` (64² images: ~3 cm a pixel)."""
    cap = open_capture(root)
    mask = cap.mask
    cap.mask = lambda v, t: ndimage.binary_dilation(mask(v, t), iterations=pixels)
    return cap
