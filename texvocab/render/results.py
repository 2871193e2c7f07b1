"""What the render paths return: per batch of rays (:class:`RayResult`), per image
(:class:`RenderResult` with its :class:`RenderStats`), and how each ray was rendered
(:class:`RayKind`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

import torch


class RenderCancelled(Exception):
    """Raised inside a render when its ``cancelled()`` callback returns True."""


class RayKind(IntEnum):
    """How the guided marcher rendered a ray (:mod:`texvocab.render.guided.triage`).
    NONE: not rendered (outside the subset, missing the shell, or left for later);
    BACKGROUND: passes every surface far away; BAND: the surface band; FALLBACK: marched by
    the shell marcher; RESIDUAL: a residual ray."""

    NONE = 0
    BACKGROUND = 1
    BAND = 2
    FALLBACK = 3
    RESIDUAL = 4

    @property
    def label(self) -> str:
        """The kind's key in :attr:`RenderStats.paths` ("band", "residual", …)."""
        return self.name.lower()


#: the kinds :attr:`RenderStats.paths` counts, in its order
COUNTED = (RayKind.BAND, RayKind.RESIDUAL, RayKind.FALLBACK, RayKind.BACKGROUND)


def count_kinds(kind: torch.Tensor) -> dict[str, int]:
    """Rays of each counted kind in ``kind`` (any shape, :class:`RayKind` codes)."""
    return {k.label: int((kind == k).sum()) for k in COUNTED}


@dataclass
class RayResult:
    """rgb (R, 3) over the background; opacity (R,); depth (R,): expected ray distance of
    the surface, sum(w t) / opacity (0 for empty rays); field_evals: points evaluated;
    kind (R,) uint8 :class:`RayKind` per ray (None: all marched by the shell marcher)."""

    rgb: torch.Tensor
    opacity: torch.Tensor
    depth: torch.Tensor
    field_evals: int
    kind: torch.Tensor | None = None

    @property
    def banded(self) -> int:
        """Rays resolved by the surface band."""
        return 0 if self.kind is None else int((self.kind == RayKind.BAND).sum())

    @property
    def residual(self) -> int:
        """Rays resolved as residual rays."""
        return 0 if self.kind is None else int((self.kind == RayKind.RESIDUAL).sum())


@dataclass
class RenderStats:
    """field_evals: points passed to the field; rays: rays rendered (hit the shell; for the
    guided marcher the band, residual and marched ones); pixels: image size; seconds: wall
    time in total; shell_seconds: of it, building the shell geometry (0 when a prebuilt one
    was passed); paths: the guided marcher's rays of each kind (:func:`count_kinds`; empty
    for the shell marcher); kind: (H, W) uint8 :class:`RayKind` per pixel (guided only)."""

    field_evals: int
    rays: int
    pixels: int
    seconds: float
    shell_seconds: float = 0.0
    paths: dict[str, int] = field(default_factory=dict)
    kind: torch.Tensor | None = None


@dataclass
class RenderResult:
    """rgb (H, W, 3), alpha (H, W), depth (H, W) (ray distance, 0 where empty), stats."""

    rgb: torch.Tensor
    alpha: torch.Tensor
    depth: torch.Tensor
    stats: RenderStats
