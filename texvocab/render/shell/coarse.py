"""The coarse pass: field evaluation front to back along each ray, with early ray
termination (:func:`march_until_opaque`, the one place that decides when a ray stops)
and scouting (:func:`coarse_pass`: every other sample first, the ones between only
where the scouts see density).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from texvocab.render.volume.field import Field, evaluate_field
from texvocab.render.volume.samples import RaySamples, midpoint_intervals


@dataclass
class Marched:
    """Coarse samples of R rays after the march: ``samples`` (R, S) (skipped ones
    removed), density ``sigma`` (R, S) and ``rgb`` (R, S, 3) (zero where not evaluated,
    i.e. after the stop), ``last`` (R,) index of each ray's last evaluated sample (-1:
    none), ``stopped`` (R,) rays terminated with T < eps, ``evals`` points evaluated."""

    samples: RaySamples
    sigma: torch.Tensor
    rgb: torch.Tensor
    last: torch.Tensor
    stopped: torch.Tensor
    evals: int


def march_until_opaque(
    field: Field,
    samples: RaySamples,
    origins: torch.Tensor,
    dirs: torch.Tensor,
    eps: float,
    segment: int,
    chunk: int,
) -> Marched:
    """Early ray termination: evaluate samples front to back, ``segment`` per ray at a
    time, and drop a ray once its transmittance T = exp(-sum sigma_j delta_j) < ``eps``.

    Samples after the stop are never evaluated (density 0). :func:`absorb` then gives a
    stopped ray's leftover transmittance (< eps) to its last evaluated sample, i.e. the
    ray is taken to end there, so the colour error is below eps times the colour change
    behind that point (rather than eps times colour minus background).

    Args:
        samples: (R, S) sorted along each ray (padding is never evaluated).
        origins, dirs: (R, 3). eps: transmittance threshold; 0 evaluates every sample.
    """
    deltas, valid = samples.deltas, samples.valid
    R, S = deltas.shape
    limit = -math.log(eps) if eps > 0 else math.inf
    optical = torch.zeros(R, dtype=deltas.dtype)
    last = torch.full((R,), -1, dtype=torch.long)
    rows, cols, sigmas, rgbs = [], [], [], []
    for s0 in range(0, S, segment):
        active = torch.nonzero((optical < limit) & valid[:, s0]).squeeze(1)
        if len(active) == 0:
            break
        r, c = torch.nonzero(valid[active, s0 : s0 + segment], as_tuple=True)
        r, c = active[r], c + s0
        sigma, rgb = evaluate_field(field, origins[r] + samples.t[r, c, None] * dirs[r], dirs[r], chunk)
        optical.index_add_(0, r, sigma.detach() * deltas[r, c])
        last[r] = c  # pairs come in row-major order: each row's largest c is written last
        rows.append(r)
        cols.append(c)
        sigmas.append(sigma)
        rgbs.append(rgb)
    stopped = optical >= limit
    if not rows:
        return Marched(samples, deltas.new_zeros(R, S), deltas.new_zeros(R, S, 3), last, stopped, 0)
    index = (torch.cat(rows), torch.cat(cols))
    sigma = torch.cat(sigmas)
    return Marched(
        samples,
        sigma.new_zeros(R, S).index_put(index, sigma),
        sigma.new_zeros(R, S, 3).index_put(index, torch.cat(rgbs)),
        last,
        stopped,
        len(index[0]),
    )


def absorb(
    marched: Marched, acc: torch.Tensor, color: torch.Tensor, depth_sum: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Give each stopped ray's leftover transmittance 1 - acc (R,) to its last evaluated
    sample: returns opacity (R,), colour (R, 3), unnormalised depth sum(w t) (R,)."""
    rows = torch.nonzero(marched.stopped & (marched.last >= 0)).squeeze(1)
    if len(rows) == 0:
        return acc, color, depth_sum
    rest = 1 - acc[rows]
    idx = marched.last[rows]
    return (
        acc.index_put((rows,), acc[rows] + rest),
        color.index_put((rows,), color[rows] + rest[:, None] * marched.rgb[rows, idx]),
        depth_sum.index_put((rows,), depth_sum[rows] + rest * marched.samples.t[rows, idx]),
    )


def coarse_pass(
    field: Field,
    samples: RaySamples,
    length: torch.Tensor,
    origins: torch.Tensor,
    dirs: torch.Tensor,
    eps: float,
    segment: int,
    chunk: int,
    scout_threshold: float | None,
) -> Marched:
    """Evaluate the coarse samples (R, S) of rays with in-shell path ``length`` (R,).

    With ``scout_threshold``, the even samples (scouts) are marched first
    (:func:`march_until_opaque`, each standing for twice the step); an odd sample is
    then evaluated only if a neighbouring scout has sigma * step >= the threshold
    (and it lies before the stop). The others are removed, their path shared by the
    neighbouring scouts: empty space costs half. Assumes the density is smooth at the
    scale of two steps (as the coarse-to-fine sampling already does). None: every
    sample is marched.
    """
    S = samples.u.shape[1]
    if scout_threshold is None or S < 3:
        return march_until_opaque(field, samples, origins, dirs, eps, segment, chunk)
    even = torch.arange(0, S, 2)
    starts, ends = midpoint_intervals(samples.u[:, even], length)
    scouts = RaySamples(samples.u[:, even], starts, ends, samples.t[:, even])
    m = march_until_opaque(field, scouts, origins, dirs, eps, segment, chunk)
    R, n_odd = len(length), S // 2
    j = torch.arange(n_odd)  # odd sample 2j + 1 sits between scouts j and j + 1
    step = (length / samples.valid.sum(1).clamp(min=1))[:, None]
    hot = (m.sigma.detach() * step) >= scout_threshold  # (R, n_scouts)
    right = torch.cat([hot[:, 1:], torch.zeros_like(hot[:, :1])], 1)[:, :n_odd]
    before_stop = (j < m.last[:, None]) | ((j == m.last[:, None]) & ~m.stopped[:, None])
    need = samples.valid[:, 1::2] & before_stop & (hot[:, :n_odd] | right)
    r, c = torch.nonzero(need, as_tuple=True)
    k = 2 * c + 1
    sigma_o, rgb_o = evaluate_field(field, origins[r] + samples.t[r, k, None] * dirs[r], dirs[r], chunk)
    n_even = len(even)
    rows = torch.cat([torch.arange(R).repeat_interleave(n_even), r])
    cols = torch.cat([even.repeat(R), k])
    sigma = m.sigma.new_zeros(R, S).index_put((rows, cols), torch.cat([m.sigma.reshape(-1), sigma_o]))
    rgb = m.rgb.new_zeros(R, S, 3).index_put((rows, cols), torch.cat([m.rgb.reshape(-1, 3), rgb_o]))
    evaluated = torch.zeros(R, S, dtype=torch.bool)
    evaluated[:, even] = torch.arange(n_even) <= m.last[:, None]
    evaluated[r, k] = True
    last = torch.where(m.last >= 0, 2 * m.last, -1)
    before = (torch.arange(S) < last[:, None]) | ~m.stopped[:, None]  # not after a stop
    skipped = samples.valid & ~evaluated & before
    u, order = torch.where(skipped, torch.inf, samples.u).sort(1)
    starts, ends = midpoint_intervals(u, length)
    kept = RaySamples(u, starts, ends, samples.t.gather(1, order))
    rank = order.argsort(1)  # old index -> new index
    last = torch.where(last >= 0, rank.gather(1, last.clamp(min=0)[:, None])[:, 0], last)
    return Marched(
        kept,
        sigma.gather(1, order),
        rgb.gather(1, order[..., None].expand(-1, -1, 3)),
        last,
        m.stopped,
        m.evals + len(r),
    )
