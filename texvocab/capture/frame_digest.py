"""What one frame's derived data was computed from, as a digest: the bytes of its image and
mask files in the given views, those views' calibration, and the frame's pose. A cache
entry that stores it (the texture maps of ``texvocab prepare``) is rebuilt when the
capture's files change, whatever their size or name."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

CHUNK = 1 << 20


def _file(h, path: Path) -> None:
    h.update(str(Path(path).name).encode())
    with open(path, "rb") as fh:
        while block := fh.read(CHUNK):
            h.update(block)


def _array(h, x) -> None:
    a = np.ascontiguousarray(np.asarray(x, dtype=np.float64))
    h.update(str(a.shape).encode())
    h.update(a.tobytes())


def frame_digest(capture, frame: int, views: list[int]) -> bytes:
    """16-byte BLAKE2b digest of ``frame``'s inputs in ``views``: image and mask bytes,
    each camera's K, R, t, distortion and size, the pose, translation and shape."""
    h = hashlib.blake2b(digest_size=16)
    for v in views:
        _file(h, capture.image_paths[frame][v])
        _file(h, capture.mask_paths[frame][v])
        cam = capture.cameras[v]
        for x in (cam.K, cam.R, cam.t, cam.dist, (cam.width, cam.height)):
            _array(h, x)
    _array(h, capture.poses[frame])
    _array(h, capture.trans[frame])
    shape = capture.shape()
    _array(h, np.zeros(0) if shape is None else shape.detach().cpu().numpy())
    return h.digest()
