"""Samples along rays and the volume-rendering quadrature shared by every marcher.

Positions along a ray are measured in a *path coordinate* ``u`` (metres): for the
uniform marcher ``u = t - near``; for the shell marcher ``u`` counts only the part of
the ray inside the shell, so gaps between limbs have zero length and cost nothing (see
:class:`texvocab.render.shell.path.ShellPath`). Each sample stands for an interval
``[start, end]`` of ``u`` (nerfacc's ``t_starts``/``t_ends``); its ``delta`` is the
interval's length.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch


@dataclass
class RaySamples:
    """Up to S samples on each of R rays (rows padded at the end).

    u: (R, S) positions in the path coordinate, sorted along each ray; +inf for padding.
    starts, ends: (R, S) the interval of path each sample stands for (empty for padding).
    t: (R, S) ray distance of each sample (world metres from the ray origin).
    """

    u: torch.Tensor
    starts: torch.Tensor
    ends: torch.Tensor
    t: torch.Tensor

    @property
    def deltas(self) -> torch.Tensor:
        """(R, S) interval lengths (0 for padding)."""
        return self.ends - self.starts

    @property
    def valid(self) -> torch.Tensor:
        """(R, S) bool: real samples (padding has an empty interval)."""
        return self.ends > self.starts

    def rows(self, idx: torch.Tensor) -> RaySamples:
        """The samples of rays ``idx`` (K,)."""
        return RaySamples(self.u[idx], self.starts[idx], self.ends[idx], self.t[idx])


def stratified_positions(
    length: torch.Tensor, step: float | None, count: int, generator: torch.Generator | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """Stratified samples on [0, length] for each ray: n = ceil(length / step) bins
    clamped to [1, count] (``step=None``: exactly ``count``).

    Args:
        length: (R,) path length per ray.
        generator: None for bin midpoints (deterministic), else uniform jitter in each bin.

    Returns:
        positions (R, N) (+inf past a ray's n) and bin edges (R, N + 1) (repeating
        ``length`` past n), N the largest n.
    """
    if step is None:
        n = torch.full(length.shape, count, dtype=torch.long)
    else:
        n = torch.ceil(length / step).long().clamp(1, count)
    N = int(n.max()) if len(n) else 1
    k = torch.arange(N + 1)
    edges = length[:, None] * (torch.minimum(k, n[:, None]).to(length.dtype) / n[:, None])
    if generator is None:
        offset = torch.full((len(length), N), 0.5, dtype=length.dtype)
    else:
        offset = torch.rand((len(length), N), generator=generator, dtype=length.dtype)
    u = edges[:, :-1] + offset * (edges[:, 1:] - edges[:, :-1])
    return torch.where(k[:-1] < n[:, None], u, torch.inf), edges


def midpoint_intervals(u: torch.Tensor, length: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Intervals (starts, ends) (R, S) of sorted positions u (R, S) on [0, length (R,)]:
    each sample owns the half-way points to its neighbours (its Voronoi cell); +inf
    entries (padding, sorted last) get the empty interval [length, length]."""
    L = length[:, None].to(u.dtype)
    valid = torch.isfinite(u)
    uu = torch.where(valid, u, L)
    mid = 0.5 * (uu[:, 1:] + uu[:, :-1])
    next_valid = torch.cat([valid[:, 1:], torch.zeros_like(valid[:, :1])], 1)
    ends = torch.where(next_valid, torch.cat([mid, L], 1), L)
    starts = torch.cat([torch.zeros_like(L), ends[:, :-1]], 1)
    return starts, ends


def composite(
    sigma: torch.Tensor, rgb: torch.Tensor, deltas: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Alpha compositing (NeRF quadrature, Max 1995), front to back.

    Args:
        sigma: (R, S) density >= 0. rgb: (R, S, 3). deltas: (R, S) interval lengths.

    Returns:
        weights (R, S) = T_i (1 - exp(-sigma_i delta_i)) with T_i = exp(-sum_{j<i}
        sigma_j delta_j); opacity (R,) = sum of weights; colour (R, 3) = sum w_i rgb_i
        (not yet over a background). Only exp of non-positive numbers is taken, so any
        finite sigma gives finite values and gradients.
    """
    tau = sigma * deltas
    alpha = -torch.expm1(-tau)
    before = torch.cat([torch.zeros_like(tau[:, :1]), torch.cumsum(tau[:, :-1], 1)], 1)
    weights = torch.exp(-before) * alpha
    return weights, weights.sum(1), (weights[..., None] * rgb).sum(1)


def dilate_weights(weights: torch.Tensor) -> torch.Tensor:
    """mip-NeRF's 2-tap max then 2-tap blur of weights (R, B) along each ray: every bin
    next to a heavy bin becomes heavy too, so fine samples also cover a surface that the
    coarse samples only bracketed."""
    pad = torch.cat([weights[:, :1], weights, weights[:, -1:]], 1)
    peak = torch.maximum(pad[:, :-1], pad[:, 1:])  # (R, B + 1)
    return 0.5 * (peak[:, :-1] + peak[:, 1:])


def sample_pdf(
    edges: torch.Tensor,
    weights: torch.Tensor,
    n: int,
    generator: torch.Generator | None = None,
    pad: float = 1e-5,
) -> torch.Tensor:
    """Inverse-CDF (importance) sampling of a piecewise-constant pdf (NeRF hierarchical
    sampling).

    Args:
        edges: (R, B + 1) bin edges, increasing. weights: (R, B) >= 0, bin masses.
        n: samples per ray.
        generator: None for the deterministic quantiles (k + 0.5) / n, else uniform
            random quantiles drawn from it.
        pad: mass spread uniformly over the bins (in proportion to their width),
            relative to the ray's total weight; keeps the pdf proper (empty rays get
            uniform samples) and never puts samples in empty-width bins.

    Returns:
        (R, n) sorted positions. Not differentiable (the result is detached).
    """
    weights = weights.detach().to(edges.dtype)
    width = edges[:, 1:] - edges[:, :-1]
    total = width.sum(1, keepdim=True)
    # a zero-length ray (all edges equal) gets equal shares, so its pdf stays proper
    share = torch.where(total > 0, width / total.clamp(min=1e-30), 1.0 / width.shape[1])
    weights = weights + (pad * weights.sum(1, keepdim=True) + 1e-12) * share
    pdf = weights / weights.sum(1, keepdim=True)
    cdf = torch.cat([torch.zeros_like(pdf[:, :1]), torch.cumsum(pdf, 1)], 1)
    cdf[:, -1] = 1.0
    if generator is None:
        q = (torch.arange(n, dtype=edges.dtype) + 0.5) / n
        q = q.expand(len(edges), n).contiguous()
    else:
        q = torch.rand((len(edges), n), generator=generator, dtype=edges.dtype).sort(1).values
    hi = torch.searchsorted(cdf, q, right=True).clamp(1, edges.shape[1] - 1)
    lo = hi - 1
    c_lo, c_hi = cdf.gather(1, lo), cdf.gather(1, hi)
    e_lo, e_hi = edges.gather(1, lo), edges.gather(1, hi)
    span = c_hi - c_lo
    frac = (q - c_lo) / torch.where(span > 1e-12, span, torch.ones_like(span))
    return (e_lo + frac.clamp(0, 1) * (e_hi - e_lo)).detach()
