"""Masks that can be a person's silhouette: neither empty (no foreground) nor full (every
pixel foreground). A capture whose masks are all empty, or all full, is refused when it is
opened; :func:`survey_masks` finds the single ones for ``check-assets``."""

from __future__ import annotations

from dataclasses import dataclass, field

from texvocab.capture.image_reader import read_mask
from texvocab.errors import AssetError

EXPECTED = "expected the person's silhouette as foreground (> 127) on a background (0)"


def check_mask_content(capture) -> None:
    """AssetError when every readable mask of ``capture`` is empty, or every one is full.

    Reads masks in frame order until one with foreground and one with background have been
    seen (on a usable capture: the first mask). Masks that are missing or unreadable are
    skipped here: ``check-assets`` and the image checks name them."""
    foreground = background = False
    read, first = 0, None
    for t in range(capture.num_frames):
        for v in range(capture.num_views):
            path = capture.mask_paths[t][v]
            try:
                mask = read_mask(path)
            except AssetError:
                continue
            read, first = read + 1, first or path
            foreground |= bool(mask.any())
            background |= not bool(mask.all())
            if foreground and background:
                return
    if read and not foreground:
        raise AssetError(f"{capture.root}: all {read} masks are empty (e.g. {first}); {EXPECTED}")
    if read and not background:
        raise AssetError(
            f"{capture.root}: all {read} masks are full: every pixel is foreground (e.g. {first}); {EXPECTED}"
        )


@dataclass
class MaskSurvey:
    """What :func:`survey_masks` found: problem lines naming files, and the (frame, view)
    of each empty and each full mask."""

    problems: list[str] = field(default_factory=list)
    empty: list[tuple[int, int]] = field(default_factory=list)
    full: list[tuple[int, int]] = field(default_factory=list)


def survey_masks(capture) -> MaskSurvey:
    """Decode every mask of ``capture`` once: unreadable ones, ones not their view's size,
    empty ones and full ones."""
    survey = MaskSurvey()
    for t in range(capture.num_frames):
        for v in range(capture.num_views):
            path = capture.mask_paths[t][v]
            try:
                mask = read_mask(path)
                capture.check_size(path, mask.shape, v)
            except AssetError as e:
                survey.problems.append(str(e))
                continue
            if not mask.any():
                survey.empty.append((t, v))
            elif mask.all():
                survey.full.append((t, v))
    return survey
