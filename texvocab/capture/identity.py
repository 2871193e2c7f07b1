"""A capture's identity, as a checkpoint records it: the layout, the number of frames and
views, the frame ids and a digest of the calibration as the reader returned it (each
view's K, R, T, distortion and image size, before any resizing on load). Computed from
the opened capture alone: no image is read.

A checkpoint stores it under ``capture_identity``; every command that loads an avatar on
a capture (``eval``, ``render``, ``shot``, ``view``, ``train --resume``) compares it with
the capture it is given and refuses another one with one line saying what differs, unless
``--other-capture`` accepts it (then one warning line says the same). A checkpoint
written before the identity existed is not checked.
"""

from __future__ import annotations

import hashlib
import logging
from pathlib import Path

import numpy as np

from texvocab.errors import TexvocabError

log = logging.getLogger("texvocab")

#: the checkpoint key holding the identity
IDENTITY_KEY = "capture_identity"
#: the flag that accepts a capture whose identity differs
ACCEPT_FLAG = "--other-capture"


def calibration_digest(capture) -> str:
    """Hex BLAKE2b digest of every view's K, R, T, distortion and image size, as read
    (``source_cameras`` of a capture resized on load)."""
    h = hashlib.blake2b(digest_size=16)
    for cam in capture.source_cameras or capture.cameras:
        for x in (cam.K, cam.R, cam.t, cam.dist, (cam.width, cam.height)):
            a = np.ascontiguousarray(np.asarray(x, dtype=np.float64))
            h.update(str(a.shape).encode())
            h.update(a.tobytes())
    return h.hexdigest()


def capture_identity(capture) -> dict:
    """What a checkpoint records of the capture it was trained on (plain types only, so
    the weights-only reader loads it)."""
    return {
        "layout": str(capture.layout),
        "num_frames": int(capture.num_frames),
        "num_views": int(capture.num_views),
        "frame_ids": [int(f) for f in capture.frame_ids],
        "calibration": calibration_digest(capture),
    }


def _readable(recorded: object) -> bool:
    return (
        isinstance(recorded, dict)
        and isinstance(recorded.get("layout"), str)
        and all(type(recorded.get(k)) is int for k in ("num_frames", "num_views"))
        and isinstance(recorded.get("frame_ids"), list)
        and len(recorded["frame_ids"]) == recorded["num_frames"]
        and all(type(f) is int for f in recorded["frame_ids"])
        and isinstance(recorded.get("calibration"), str)
    )


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}{'' if n == 1 else 's'}"


def identity_differences(recorded: dict, current: dict) -> list[str]:
    """What differs between two identities, in words ("540 frames, expected 60"; the
    expected values are ``recorded``'s); empty when they are the same capture."""
    out = []
    if current["layout"] != recorded["layout"]:
        out.append(f"layout {current['layout']}, expected {recorded['layout']}")
    if current["num_frames"] != recorded["num_frames"]:
        out.append(f"{_count(current['num_frames'], 'frame')}, expected {recorded['num_frames']}")
    elif current["frame_ids"] != recorded["frame_ids"]:
        i = next(i for i, (a, b) in enumerate(zip(current["frame_ids"], recorded["frame_ids"])) if a != b)
        out.append(
            f"frame ids differ (frame {i} is {current['frame_ids'][i]}, expected {recorded['frame_ids'][i]})"
        )
    if current["num_views"] != recorded["num_views"]:
        out.append(f"{_count(current['num_views'], 'view')}, expected {recorded['num_views']}")
    elif current["calibration"] != recorded["calibration"]:
        out.append("calibration differs")
    return out


def check_capture_identity(
    checkpoint: dict, capture, path: str | Path, other_capture: bool = False
) -> list[str]:
    """Compare the identity checkpoint dict ``checkpoint`` (read from ``path``) records
    with ``capture``'s. Another capture raises TexvocabError naming both and what differs,
    unless ``other_capture``: then one warning line says it. Returns the differences
    (empty: the same capture, or a checkpoint that records no identity)."""
    if IDENTITY_KEY not in checkpoint:
        return []  # written before checkpoints recorded it
    recorded = checkpoint[IDENTITY_KEY]
    if not _readable(recorded):
        raise TexvocabError(
            f"{path}: its {IDENTITY_KEY} is not readable (expected layout, num_frames, "
            "num_views, frame_ids and calibration); see assets_spec/checkpoint.md"
        )
    diffs = identity_differences(recorded, capture_identity(capture))
    if not diffs:
        return diffs
    what = f"{path} was trained on another capture than {capture.root} ({'; '.join(diffs)})"
    if not other_capture:
        raise TexvocabError(f"{what}; pass {ACCEPT_FLAG} to use it anyway")
    log.warning("warning: %s; using it as %s asks", what, ACCEPT_FLAG)
    return diffs
