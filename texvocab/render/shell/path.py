"""The part of each ray inside the shell: :func:`trace_path` walks each ray from near to far
in steps of half a voxel and keeps the steps whose midpoint lies in the shell's occupancy
grid (:class:`~texvocab.render.shell.geometry.ShellGeometry`); the samples of the shell
marcher are then placed along the kept path, gaps removed (:class:`ShellPath`)."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from texvocab.render.shell.geometry import ShellGeometry


@dataclass
class ShellPath:
    """The part of each ray that lies in the shell, as a map from the path coordinate u
    (metres of in-shell ray, gaps removed) to the ray distance t.

    near: (R,) where the walk starts. cell: (R,) step length. u_end: (R, M) path length
    up to the end of each step (steps outside the shell add nothing).
    """

    near: torch.Tensor
    cell: torch.Tensor
    u_end: torch.Tensor

    @property
    def length(self) -> torch.Tensor:
        """(R,) in-shell path length of each ray."""
        return self.u_end[:, -1]

    def rows(self, index: torch.Tensor) -> "ShellPath":
        """The paths of rays ``index`` (K,)."""
        return ShellPath(self.near[index], self.cell[index], self.u_end[index])

    def to_t(self, u: torch.Tensor) -> torch.Tensor:
        """Ray distances (R, K) of path positions u (R, K) in [0, length]."""
        j = torch.searchsorted(self.u_end, u.contiguous()).clamp(max=self.u_end.shape[1] - 1)
        cell_end = self.near[:, None] + (j + 1).to(u.dtype) * self.cell[:, None]
        return cell_end - (self.u_end.gather(1, j) - u)


def trace_path(
    shell: ShellGeometry | None,
    origins: torch.Tensor,
    dirs: torch.Tensor,
    near: torch.Tensor,
    far: torch.Tensor,
) -> ShellPath:
    """Walk rays (origins, dirs (R, 3)) from near to far (R,) and keep the steps inside
    the shell's occupancy grid. ``shell=None`` keeps all of [near, far] (one step)."""
    span = (far - near).clamp(min=0)
    if shell is None:
        return ShellPath(near, span, span[:, None])
    s = shell.step
    m = torch.ceil(span / s).long()
    j = torch.arange(max(int(m.max()) if len(m) else 0, 1))
    rows, cols = torch.nonzero(j < m[:, None], as_tuple=True)
    t = near[rows] + (cols.to(near.dtype) + 0.5) * s
    occ = torch.zeros((len(near), len(j)), dtype=near.dtype)
    occ[rows, cols] = shell.contains(origins[rows] + t[:, None] * dirs[rows]).to(near.dtype)
    return ShellPath(near, torch.full_like(near, s), torch.cumsum(occ * s, 1))
