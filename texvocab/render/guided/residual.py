"""Residual rays: the rays the surface band cannot take (silhouette fringes that pass
close to the surface, grazing hits, hits behind an occlusion edge, bands that do not
bracket the surface), rendered from the mesh's distance along the ray plus the field's
residual, with three field evaluations per ray instead of a march.

The avatar's SDF is the posed body's signed distance d plus a residual r (Sec. 3.5: the
SDF network's output on top of the body, :class:`texvocab.method.field.AvatarField`).
Along these rays the SDF is curved where the density lives (a ray running past or into
a convex body at a low angle), which is why a few straight chords between field samples
misjudge the density and why marching needs ~20 samples per ray. But the curvature is
the mesh's, and d is exact and cheap (a
:class:`~texvocab.geometry.surface.SurfaceIndex` query, no network), while the residual
varies slowly there (measured on a trained avatar's silhouette fringe: a density-weighted
spread of 0.1 β median, 0.3 β at the 90th percentile). So per ray:

1. d every 4 ``residual_step`` β over the ray's shell interval [near, far]; with the
   residual r0 of the ray's probe, ŝ = d + r0 estimates the SDF. d is 1-Lipschitz, so
   between two samples ŝ stays above their mean minus half the step: that bounds the
   part of the ray that matters — where ŝ may be within 6 β of max(least ŝ, 0) (beyond
   it the density is below e^-6 of its peak), up to where the ray is opaque (optical
   depth 8). With ``residual_levels`` L > 0 the same test first runs at 4^(L+1), …, 4²
   ``residual_step`` β, each pass on the part the coarser one kept: the bound is looser
   at a longer step, so a coarse pass keeps at least what a finer one would, and a ray
   through the body (its shell interval 20–30 cm) is sampled finely only around where
   it enters.
2. d every ``residual_step`` β over that part, the weights ŝ gives it, and three field
   evaluations at the ``residual_spread``, 1/2 and 1 - ``residual_spread`` quantiles
   of those weights.
3. The SDF d + r with r (and the colour) interpolated linearly between the three, its
   opacity the closed-form VolSDF integral over the dense samples
   (:func:`~texvocab.render.volume.volsdf.composite_linear_sdf`).

A ray is left to the marcher (``ok`` False) when no part of it comes close enough, or
when the weights of the final SDF have their median outside the span of the three
evaluations (the residual moved the surface away from where ŝ put it).
"""

from __future__ import annotations

import math

import numpy as np
import torch

from texvocab.render.guided.band import interpolate_knots, no_rays, put_rows
from texvocab.render.guided.residual_quadrature import compiled_quadrature, evaluate_knots
from texvocab.render.guided.residual_samples import ragged_mesh_samples
from texvocab.render.settings import MarchSettings
from texvocab.render.volume.field import points_along
from texvocab.render.volume.volsdf import (
    beta_value,
    composite_linear_sdf,
    interval_optical_depth,
    linear_sdf_weights,
)

_COARSE = 4  # the coarse pass's step, in dense steps
_KEEP = 6.0  # the part of a ray that matters: ŝ within this many β of max(least, 0)
_OPAQUE = 8.0  # ... up to this optical depth (transmittance 3e-4)


def mesh_distance(index, points: torch.Tensor, cap: float, known: torch.Tensor | None = None) -> torch.Tensor:
    """Signed distance (N,) of points (N, 3) to the indexed mesh, ``cap`` beyond cap.
    ``known`` (N,) long: closest faces known already (-1: search)."""
    return mesh_distance_faces(index, points, cap, known)[0]


def mesh_distance_faces(
    index, points: torch.Tensor, cap: float, known: torch.Tensor | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`mesh_distance` and the closest face (N,) long of each point (-1 beyond cap)."""
    if len(points) == 0:
        return points.new_zeros(0), torch.zeros(0, dtype=torch.long)
    known = None if known is None else known.numpy()
    proj = index.project(points.detach().double().numpy(), max_distance=cap, known=known)
    d = torch.from_numpy(np.where(proj.face >= 0, proj.distance, cap)).to(points.dtype)
    return d, torch.from_numpy(proj.face)


def _estimate(d: torch.Tensor, r0: torch.Tensor, cap: float) -> torch.Tensor:
    """ŝ = d + r0, the SDF estimated from mesh distances d (R, M) and the probe's
    residual r0 (R, 1); ``cap`` beyond the shell."""
    return torch.where(d < cap, d + r0, cap)


def _samples(index, origin, dirs, near, far, step: float, cap: float):
    """d every ``step`` over [near, far] (R,): t, d (R, M), their closest faces f (R, M)
    (-1 beyond cap) and ``inside`` (R, M) (columns past far repeat the last one)."""
    last = torch.ceil((far - near).clamp(min=0) / step).long().clamp(min=1)
    M = int(last.max()) + 1
    col = torch.arange(M)
    t = torch.minimum(near[:, None] + col * step, far[:, None])
    inside = col <= last[:, None]
    d = torch.full(t.shape, cap, dtype=dirs.dtype)
    f = torch.full(t.shape, -1, dtype=torch.long)
    d[inside], f[inside] = mesh_distance_faces(index, points_along(origin, dirs, t)[inside], cap)
    end = last[:, None]
    return t, torch.where(inside, d, d.gather(1, end)), torch.where(inside, f, f.gather(1, end)), inside


def _narrow(index, origin, dirs, near, far, step: float, r0, beta: float, cap: float, levels: int):
    """[near, far] (R,) narrowed to the part that matters by ``levels`` passes of
    :func:`_part_that_matters` at step·4^levels, …, step·4 (none: unchanged), and found
    (R,) (False: a pass found no low interval; such a ray's interval is left empty)."""
    found = torch.ones(len(dirs), dtype=torch.bool)
    for k in range(levels, 0, -1):
        t, d, _, inside = _samples(index, origin, dirs, near, far, step * _COARSE**k, cap)
        _, first, end, ok = _part_that_matters(t, _estimate(d, r0, cap), inside, beta)
        found &= ok
        near = t.gather(1, first[:, None])[:, 0]
        # one interval more: the chords' opacity may come early where the body is concave
        last = (end + 1).clamp(max=t.shape[1] - 1)
        far = torch.where(found, t.gather(1, last[:, None])[:, 0], near)
    return near, far, found


def _part_that_matters(
    t: torch.Tensor, s: torch.Tensor, inside: torch.Tensor, beta: float
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """From coarse samples t, ŝ (R, M): the intervals where ŝ may be within _KEEP β of
    max(least, 0) ("low"), up to where the ray is opaque (optical depth _OPAQUE, from
    straight chords between the samples, which under-count a convex SDF's density: the
    cut comes late, not early). Returns low (R, M - 1), the first and the end column of
    the part (R,) (intervals first..end-1) and found (R,) (False: no low interval)."""
    M = t.shape[1]
    col = torch.arange(M - 1)
    least = s.masked_fill(~inside, math.inf).amin(1, keepdim=True)
    dt = t[:, 1:] - t[:, :-1]
    bound = (s[:, :-1] + s[:, 1:] - dt) / 2  # lower bound per interval
    low = (bound <= least.clamp(min=0) + _KEEP * beta) & inside[:, 1:]
    found = low.any(1)
    first = torch.where(low, col, M).amin(1).clamp(max=M - 2)
    tau = interval_optical_depth(s[:, :-1], s[:, 1:], dt, beta)
    deep = (torch.cumsum(tau, 1) >= _OPAQUE) & inside[:, 1:] & (col >= first[:, None])
    end = torch.minimum(torch.where(low, col, -1).amax(1).clamp(min=0), torch.where(deep, col, M).amin(1)) + 1
    low &= col < end[:, None]
    return low, first, end, found


def _refine(index, origin, dirs, t_c, d_c, f_c, low, first, end, cap: float):
    """The coarse samples t_c, d_c and their faces f_c (R, M) of the part first..end (R,),
    with _COARSE - 1 more in each low interval (R, M - 1): t, d, f (R, N) sorted (a ray
    with fewer than N repeats its last) and the number of samples per ray (R,)."""
    R, M = t_c.shape
    k = torch.arange(_COARSE, dtype=t_c.dtype) / _COARSE
    col = torch.arange(M - 1)
    lo, hi = t_c[:, :-1, None], t_c[:, 1:, None]
    t = lo + k * (hi - lo)  # (R, M - 1, F): each interval's start and its refinements
    part = (col >= first[:, None]) & (col < end[:, None])
    keep = part[..., None] & ((k == 0) | low[..., None])
    d = d_c[:, :-1, None].expand_as(t).clone()
    f = f_c[:, :-1, None].expand_as(t).clone()
    new = keep & (k > 0)
    r, c, j = torch.nonzero(new, as_tuple=True)  # the new samples' points only
    at = points_along(origin if origin.dim() == 1 else origin[r], dirs[r], t[r, c, j])
    d[new], f[new] = mesh_distance_faces(index, at, cap)
    t = torch.cat([t.reshape(R, -1), t_c.gather(1, end[:, None])], 1)
    d = torch.cat([d.reshape(R, -1), d_c.gather(1, end[:, None])], 1)
    f = torch.cat([f.reshape(R, -1), f_c.gather(1, end[:, None])], 1)
    keep = torch.cat([keep.reshape(R, -1), torch.ones(R, 1, dtype=torch.bool)], 1)
    # t is sorted along each row already: pack the kept columns to the front
    count = keep.sum(1)
    N = int(count.max())
    rows, cols = torch.nonzero(keep, as_tuple=True)
    slot = (torch.cumsum(keep, 1) - 1)[rows, cols]
    inside = torch.arange(N) < count[:, None]
    last = (count - 1)[:, None]
    packed = []
    for v in (t, d, f):
        p = torch.empty(R, N, dtype=v.dtype)
        p[rows, slot] = v[rows, cols]
        packed.append(torch.where(inside, p, p.gather(1, last)))
    return (*packed, count)


def padded_mesh_samples(
    index, origin, dirs, near, far, step: float, r0, beta: float, cap: float, levels: int
):
    """Steps 1-2 of the module docstring for rays (R,) over [near, far] (R,) with the
    probe's residual r0 (R, 1): their mesh samples t, d (R, N) and faces f (R, N) (each
    ray's run sorted, then its last repeated), the sample count (R,) and found (R,) (False:
    no part of the ray matters). ``step`` is the 4 ``residual_step`` β pass's. Torch
    arrays padded to the longest ray: the reference :func:`compiled_mesh_samples` matches."""
    near, far, narrowed = _narrow(index, origin, dirs, near, far, step, r0, beta, cap, levels)
    t, d, f, inside = _samples(index, origin, dirs, near, far, step, cap)
    low, first, end, found = _part_that_matters(t, _estimate(d, r0, cap), inside, beta)
    t, d, f, count = _refine(index, origin, dirs, t, d, f, low, first, end, cap)
    return t, d, f, count, found & narrowed


def compiled_mesh_samples(
    index, origin, dirs, near, far, step: float, r0, beta: float, cap: float, levels: int
):
    """:func:`padded_mesh_samples` ray by ray, compiled, without the padding
    (:func:`~texvocab.render.guided.residual_samples.ragged_mesh_samples`)."""

    def query(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d, f = mesh_distance_faces(index, torch.from_numpy(points), cap)
        return d.numpy(), f.numpy()

    return ragged_mesh_samples(
        query, origin, dirs, near, far, step, r0, beta, cap, levels, _COARSE, _KEEP, _OPAQUE
    )


#: the residual rays' mesh samples (bench/render_timing.py swaps in the padded reference for
#: the ``previous`` path)
mesh_samples = compiled_mesh_samples


def _quantile_columns(weights: torch.Tensor, qs: tuple[float, ...]) -> torch.Tensor:
    """(R, len(qs)) the first column where the cumulative weight (R, M) reaches each
    quantile (uniform where a row has no weight)."""
    w = weights + 1e-12
    cum = torch.cumsum(w, 1) / w.sum(1, keepdim=True)
    q = torch.tensor(qs, dtype=cum.dtype).expand(len(cum), -1).contiguous()
    return torch.searchsorted(cum, q).clamp(max=cum.shape[1] - 1)


def _column_weights(t: torch.Tensor, s: torch.Tensor, beta: float) -> torch.Tensor:
    """The linear-SDF quadrature's weights per column (R, M), without the part in front
    of the first sample: each interval's to its far end, what the last absorbs to it."""
    w, ends, _ = linear_sdf_weights(t, s, beta, front=False)
    w[:, -1] += ends
    return w


def render_residual(
    field,
    index,
    origin: torch.Tensor,
    dirs: torch.Tensor,
    near: torch.Tensor,
    far: torch.Tensor,
    t_probe: torch.Tensor,
    sdf_probe: torch.Tensor,
    beta,
    settings: MarchSettings,
    probe_face: torch.Tensor | None = None,
):
    """Residual rays (R,) from origin (3,) or origins (R, 3) along dirs (R, 3), in the
    shell over [near, far] (R,), with probes at t_probe (R, P) that read field SDF
    sdf_probe (R, P) (inf where a ray has fewer probes; every ray has one) and whose
    closest mesh faces are probe_face (R, P) where known (-1 elsewhere; None: none).

    Differentiable w.r.t. the three evaluations and ``beta`` (a float, or the model's β
    tensor as training passes it); the probes, the knots' places and ``ok`` carry no
    gradient.

    ``field.sdf_rgb`` is evaluated at 3 points per ray, on three of the mesh samples:
    with ``settings.surface_reuse`` their closest faces go with them (the field's
    projection does not search again). ``index`` is the posed mesh's
    :class:`~texvocab.geometry.surface.SurfaceIndex`. Knobs from ``settings``
    (:class:`~texvocab.render.settings.MarchSettings`): the residual group, the shell's
    width (distances beyond it read as it) and the field call's chunk.

    Returns opacity (R,), colour (R, 3) (not over a background), depth (R,), ok (R,)
    (rays resolved; the others must be marched) and the number of field evaluations.
    """
    R = len(dirs)
    if R == 0:
        return (*no_rays(dirs), 0)
    b = beta_value(beta)
    cap, h = float(settings.shell.width), settings.residual.step * b
    sdf_probe = sdf_probe.detach()
    # the residual at the probe nearest the surface (a hit's own surface before an edge
    # it passes) stands for the ray's until the field is evaluated
    has = torch.isfinite(sdf_probe)
    pts = points_along(origin, dirs, torch.where(has, t_probe, 0.0))
    if settings.surface_reuse:  # only the probes a ray has: the residual is read at one
        d_probe = torch.full(has.shape, cap, dtype=dirs.dtype)
        known = None if probe_face is None else probe_face[has]
        d_probe[has] = mesh_distance(index, pts[has], cap, known)
    else:
        d_probe = mesh_distance(index, pts.reshape(-1, 3), cap).view(R, -1)
    j = sdf_probe.abs().masked_fill(~has, math.inf).argmin(1, keepdim=True)
    r0 = (sdf_probe - d_probe).gather(1, j)
    shell_near, shell_far = near, far  # a retry narrows the whole interval again
    t, d, f, count, found = mesh_samples(
        index, origin, dirs, near, far, _COARSE * h, r0, b, cap, settings.residual.levels
    )
    # rendering (β a float) takes the compiled quadrature, training (the model's β
    # tensor) torch's, which is differentiable
    learning = torch.is_tensor(beta) and beta.requires_grad and torch.is_grad_enabled()
    compiled = quadrature_compiled and not learning
    quadrature = compiled_quadrature if compiled else grouped_quadrature
    knots, knot_faces, sdf3, (acc, color, depth, ok) = quadrature(
        field, origin, dirs, t, d, f, count, r0, beta, settings
    )
    ok, evals = ok & found, 3 * R
    redo = torch.nonzero(~ok & found).squeeze(1)
    if settings.residual.retries > 0 and len(redo):
        # the three evaluations as the probes of a second try
        knots, sdf3 = knots[redo], sdf3.detach()[redo]
        faces = None if knot_faces is None else knot_faces[redo]
        fewer = settings.replace(residual_retries=settings.residual.retries - 1)
        o = origin if origin.dim() == 1 else origin[redo]
        *again, n = render_residual(
            field, index, o, dirs[redo], shell_near[redo], shell_far[redo], knots, sdf3, beta, fewer, faces
        )
        evals += n
        acc, color, depth, ok = put_rows(redo, (acc, color, depth, ok), again)
    return acc, color, depth, ok, evals


def grouped_quadrature(field, origin, dirs, t, d, f, count, r0, beta, settings: MarchSettings):
    """Steps 2-3 of the module docstring in torch (differentiable w.r.t. the evaluations and
    β) for rays (R,) with mesh samples t, d, f (R, N) (``count`` (R,) each), the rays in
    ``residual.groups`` groups of similar sample counts, each group's arrays as long as its
    longest ray (the counts vary several-fold: one array for all was mostly padding).
    Returns the knots (R, 3), their faces (R, 3) (None without ``surface_reuse``), the
    field's SDF there (R, 3) and (opacity, colour, depth, ok) of :func:`_resolve`."""
    R = len(dirs)
    b, cap = beta_value(beta), float(settings.shell.width)
    n_groups = max(settings.residual.groups, 1)
    by_count = count.argsort() if n_groups > 1 else torch.arange(R)
    groups = [g for g in torch.tensor_split(by_count, n_groups) if len(g)]
    spread, parts = settings.residual.spread, []
    for rows in groups:
        n = int(count[rows].max())
        tg, dg, fg = t[rows, :n], d[rows, :n], f[rows, :n]
        cols = _quantile_columns(
            _column_weights(tg, _estimate(dg, r0[rows], cap), b), (spread, 0.5, 1 - spread)
        )
        parts.append((rows, tg, dg, cols, tg.gather(1, cols), fg.gather(1, cols)))
    order = torch.cat([p[0] for p in parts])
    knots = torch.cat([p[4] for p in parts])
    knot_faces = torch.cat([p[5] for p in parts]) if settings.surface_reuse else None
    sdf3, rgb3 = evaluate_knots(field, origin, dirs, order, knots, knot_faces, settings)
    out, start = [], 0
    for rows, tg, dg, cols, kg, _ in parts:
        sl = slice(start, start + len(rows))
        start += len(rows)
        out.append(
            _resolve(
                tg, dg, cols, kg, sdf3.view(-1, 3)[sl], rgb3.view(-1, 3, 3)[sl], r0[rows], beta, settings
            )
        )
    back = torch.empty_like(order)
    back[order] = torch.arange(R)
    faces = None if knot_faces is None else knot_faces[back]
    return knots[back], faces, sdf3.view(-1, 3)[back], tuple(torch.cat(v)[back] for v in zip(*out))


#: the compiled quadrature at render time (bench/render_timing.py turns it off for the
#: ``previous`` path)
quadrature_compiled = True


def _resolve(t, d, cols, knots, sdf3, rgb3, r0, beta, settings: MarchSettings):
    """Rays (G,) with mesh samples t, d (G, N), the columns cols (G, 3) of their three
    evaluations at knots (G, 3), which read SDF sdf3 (G, 3) and colour rgb3 (G, 3, 3), and
    the probe's residual r0 (G, 1): opacity, colour (G, 3), depth and ok (G,) (but for
    ``found``)."""
    b, cap = beta_value(beta), float(settings.shell.width)
    resid = sdf3 - d.gather(1, cols)
    sdf = torch.where(d < cap, d + interpolate_knots(t, knots, resid), cap)
    acc, color, depth, _ = composite_linear_sdf(t, sdf, interpolate_knots(t, knots, rgb3), beta, front=False)
    median = _quantile_columns(_column_weights(t, sdf.detach(), b), (0.5,))[:, 0]
    faint = acc.detach() < 1e-4  # shows nothing: where its weight sits does not matter
    spread_r = torch.cat([resid.detach(), r0], 1)
    smooth = spread_r.amax(1) - spread_r.amin(1) <= settings.residual.tolerance * b
    # a faint ray is taken only where the field's residual is the probe's: otherwise the
    # surface may lie where the probe's residual did not put it (cloth off the body)
    ok = smooth & (faint | ((median >= cols[:, 0]) & (median <= cols[:, 2])))
    return acc, color, depth, ok
