"""Learned feature planes over the canonical body: a position encoding that fits detail fast.

γ(x_c)'s sines and cosines hand the SDF network a fixed basis; what it draws from them at
a centimetre's scale it learns slowly through the network's weights. Three axis-aligned
planes of learned features (a tri-plane, as in EG3D, Chan et al. 2022) over the canonical
body's box give each point its own features instead: x_c's projections onto the xy, xz
and yz planes each read ``channels`` features by bilinear interpolation, and the three are
concatenated to γ(x_c) (``field.position_encoding=triplane``). The features start at zero,
so a new field starts as the plain one does (the body itself; the SDF network's inputs
only gain columns of zeros).

Interpolation is written with gathers and products, not ``grid_sample``: its value is a
polynomial in x_c within each cell, so autograd's gradient with respect to x_c, and the
gradient of that gradient (the eikonal term's), are exact.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

#: (first axis, second axis) of each plane: xy, xz, yz
PLANE_AXES = ((0, 1), (0, 2), (1, 2))
PLANE_AXES_A = torch.tensor([a for a, _ in PLANE_AXES])
PLANE_AXES_B = torch.tensor([b for _, b in PLANE_AXES])


class CanonicalTriplane(nn.Module):
    """Three (resolution, resolution, channels) feature planes over the box [lo, hi] of
    canonical space; outside the box a point reads the box's edge."""

    def __init__(self, lo: torch.Tensor, hi: torch.Tensor, resolution: int, channels: int):
        super().__init__()
        lo = torch.as_tensor(lo, dtype=torch.float32).reshape(3)
        hi = torch.as_tensor(hi, dtype=torch.float32).reshape(3)
        if resolution < 2 or channels < 1 or not bool((hi > lo).all()):
            raise ValueError(
                f"triplane: needs resolution >= 2, channels >= 1 and hi > lo, got {resolution}, {channels}"
            )
        self.resolution = int(resolution)
        self.channels = int(channels)
        # the box is part of the model: saved with the weights, so a loaded field reads
        # its planes where it learned them even if the body's rest shape were rebuilt
        self.register_buffer("lo", lo)
        self.register_buffer("hi", hi)
        self.planes = nn.Parameter(torch.zeros(3, self.resolution * self.resolution, self.channels))

    @property
    def out_dim(self) -> int:
        return 3 * self.channels

    def forward(self, x_c: torch.Tensor) -> torch.Tensor:
        """Features of canonical points x_c (N, 3): (N, 3 * channels), in x_c's dtype."""
        r = self.resolution
        u = ((x_c - self.lo.to(x_c)) / (self.hi - self.lo).to(x_c)).clamp(0.0, 1.0) * (r - 1)
        # a non-finite x_c (a diverged run) reads the box's corner here, so that the lookup
        # stays in the table; γ(x_c) still carries the NaN to the SDF, and the loss reads it
        u = torch.nan_to_num(u, nan=0.0)
        cell = u.detach().floor().clamp(max=r - 2)
        frac = u - cell  # (N, 3), differentiable in x_c
        cell = cell.long()
        a, b = PLANE_AXES_A.to(x_c.device), PLANE_AXES_B.to(x_c.device)
        # each plane's cell (N, 3) in the three planes' table, then its four corners
        base = cell[:, a] * r + cell[:, b] + torch.arange(3, device=x_c.device) * (r * r)
        corners = base[:, :, None] + torch.tensor([0, 1, r, r + 1], device=x_c.device)
        n = x_c.shape[0]
        # one lookup for the twelve corners: a single gather forward and scatter backward
        f = F.embedding(corners.reshape(n, 12), self.planes.reshape(-1, self.channels))
        fa, fb = frac[:, a], frac[:, b]  # (N, 3)
        w = torch.stack([(1 - fa) * (1 - fb), (1 - fa) * fb, fa * (1 - fb), fa * fb], -1)
        out = (f.reshape(n, 3, 4, self.channels) * w[..., None].to(f.dtype)).sum(2)
        return out.reshape(n, self.out_dim).to(x_c.dtype)


def canonical_box(rest_vertices: torch.Tensor, margin: float) -> tuple[torch.Tensor, torch.Tensor]:
    """The box around the canonical body's vertices (V, 3), widened by ``margin`` (m) on
    every side: (lo (3,), hi (3,))."""
    v = torch.as_tensor(rest_vertices, dtype=torch.float32)
    return v.amin(0) - margin, v.amax(0) + margin
