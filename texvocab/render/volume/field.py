"""Calling the field: the marchers take it as a callback, ``field(points (N, 3), dirs (N, 3))
-> (density (N,) >= 0, rgb (N, 3) in [0, 1])`` (the surface-guided marcher also reads
``field.sdf_rgb(points, dirs) -> (sdf (N,), rgb (N, 3))`` and ``field.beta``), and know
nothing of the network or the vocabulary."""

from __future__ import annotations

from collections.abc import Callable

import torch

Field = Callable[[torch.Tensor, torch.Tensor], tuple[torch.Tensor, torch.Tensor]]


def evaluate_field(
    field: Field, points: torch.Tensor, dirs: torch.Tensor, chunk: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """Call ``field`` on points, dirs (N, 3) in chunks; returns density (N,), rgb (N, 3)."""
    sigmas, rgbs = [], []
    for s in range(0, len(points), chunk):
        sigma, rgb = field(points[s : s + chunk], dirs[s : s + chunk])
        n = len(points[s : s + chunk])
        if sigma.shape != (n,) or rgb.shape != (n, 3):
            raise ValueError(
                f"field must return density ({n},) and rgb ({n}, 3), got "
                f"{tuple(sigma.shape)} and {tuple(rgb.shape)}"
            )
        sigmas.append(sigma)
        rgbs.append(rgb)
    if not sigmas:
        return points.new_zeros(0), points.new_zeros(0, 3)
    return torch.cat(sigmas), torch.cat(rgbs)


def evaluate_sdf(
    field, points: torch.Tensor, dirs: torch.Tensor, chunk: int, known: torch.Tensor | None = None
):
    """(sdf (N,), rgb (N, 3)) of ``field.sdf_rgb`` in chunks. ``known`` (N,) long: the
    points' closest mesh faces where known (-1 elsewhere), passed on to a field that
    takes them (``field.takes_known``: :class:`~texvocab.method.field.PoseField`) and
    dropped for others."""
    if len(points) == 0:
        return points.new_zeros(0), points.new_zeros(0, 3)
    if known is None or not getattr(field, "takes_known", False):
        return evaluate_field(field.sdf_rgb, points, dirs, chunk)
    sdfs, rgbs = [], []
    for s in range(0, len(points), chunk):
        sdf, rgb = field.sdf_rgb(points[s : s + chunk], dirs[s : s + chunk], known=known[s : s + chunk])
        sdfs.append(sdf)
        rgbs.append(rgb)
    return torch.cat(sdfs), torch.cat(rgbs)


def points_along(origin: torch.Tensor, dirs: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """Points (R, ..., 3) at distances t (R, ...) along rays from origin (3,) or (R, 3)
    in directions dirs (R, 3)."""
    lead = (len(dirs),) + (1,) * (t.dim() - 1) + (3,)
    o = origin if origin.dim() == 1 else origin.view(lead)
    return o + t[..., None] * dirs.view(lead)
