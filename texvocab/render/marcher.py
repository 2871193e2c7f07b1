"""Coarse-to-fine ray marcher inside the thin shell around the posed body: the NeRF
volume rendering of TexVocab's "Preliminary" (Eq. 1 field; "following NeRF, we render
the images using output density values and color values"), the density coming from the
field's SDF via VolSDF ("Training" section).

The marcher takes the field as a callback, ``field(points (N, 3), dirs (N, 3)) ->
(density (N,) >= 0, rgb (N, 3) in [0, 1])``, and knows nothing of the network or the
vocabulary. Per image: rays that miss the δ-shell are never generated
(:meth:`ShellGeometry.image_bounds`); along the others only the in-shell path counts
(:func:`trace_path`), so gaps between limbs and empty space cost no field evaluations.
Per ray: stratified coarse samples every 2δ / ``coarse_samples`` metres of in-shell
path, evaluated front to back with early termination (:func:`march_until_opaque`) and
every other one only where the field shows density (:func:`coarse_pass`); then
``fine_samples`` drawn by inverse-CDF sampling of the (dilated) coarse weights
(:func:`sample_pdf`); the union of both composited over the background.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import torch

from texvocab.render.coarse import Field, absorb, coarse_pass, evaluate_field
from texvocab.render.samples import (
    RaySamples,
    composite,
    dilate_weights,
    midpoint_intervals,
    sample_pdf,
    stratified_positions,
)
from texvocab.render.shell import ShellGeometry, ShellPath, trace_path


@dataclass
class MarchSettings:
    """Knobs of the shell marcher; each trades speed (field evaluations) for accuracy.

    shell_width: δ, metres. Only points within δ of the posed mesh are sampled. Smaller
        is faster but cuts off surface the field has moved away from the mesh (clothes,
        hair), and a ray entering the body keeps only ~δ of interior: its leftover
        transmittance is about exp(-δ/β) for a VolSDF density, so keep δ >= 7β.
    shell_voxel: occupancy-grid voxel, metres. The sampled path reaches up to about
        δ + 0.9 voxel from the mesh: smaller wastes fewer samples next to the shell but
        costs a bigger grid per pose (cubic in 1/voxel).
    shell_exact: settle the grid voxels near the shell's boundary with exact distances
        (a SurfaceIndex query per pose, ~0.1 s) instead of keeping them all (looser
        shell, about 20% more samples).
    skip_empty: True places samples only on the in-shell path (occupancy grid); False
        spreads them uniformly over [near, far] of the bounding balls (gaps included).
    coarse_samples: coarse samples per crossing of the shell: the coarse step along the
        in-shell path is 2δ / coarse_samples (stratified), so a ray crossing the shell
        along its normal gets this many and a ray grazing it fewer (18: 4.4 mm for δ = 4
        cm, measured in bench/marcher.py for β of 2-4 mm). Keep the step within about
        2β of the field: a coarser step may miss a sharp or thin surface, which the fine
        pass then never finds. Early termination stops most rays shortly after the
        first surface, so longer paths cost little more.
    max_coarse: cap on coarse samples per ray (long paths, e.g. a camera inside the
        body, get a larger step instead).
    fine_samples: importance samples per ray (inverse CDF of the coarse weights).
    dilate: spread the coarse weights to neighbouring bins before importance sampling
        (mip-NeRF's max-blur), so fine samples also cover a surface that fell between
        two coarse samples; costs nothing, and makes a coarser step usable.
    scout_threshold: coarse samples are first evaluated every other one ("scouts"); a
        sample between two scouts is evaluated only if one of them has sigma * step at
        least this (None: evaluate all). Empty shell then costs half; higher values
        save more but may step over faint or thin density.
    segment: coarse samples (scouts) per ray evaluated per step of the front-to-back
        march; a ray evaluates up to segment - 1 of them past the point where it became
        opaque, while a small segment means more, smaller field calls.
    early_stop_eps: a ray stops marching once its transmittance drops below this, and
        the leftover goes to its last evaluated sample: the colour error per ray is at
        most eps times the colour change behind that point; 0 disables the stop.
    empty_opacity: rays whose coarse opacity stays below this get no fine samples (they
        graze the shell but not the surface); their colour is off by at most this.
    chunk_rays: rays per batch (memory).  chunk_points: points per field call (memory).
    guide: "shell" marches every ray through the shell front to back (above); "raster"
        is the surface-guided marcher (:mod:`texvocab.render.guided`): the mesh's
        rasterisation and the field's SDF place ``band_samples`` samples ``band_spacing``
        β / cos apart around each ray's surface, composited in closed form; rays behind
        an occlusion edge, meeting faces at a cosine below ``min_cos``, passing within
        ``miss_margin`` β of the surface outside the silhouette, or whose samples do not
        bracket the surface (or leave more than ``band_leftover`` transmittance) fall
        back to this shell marcher with ``fallback_segment`` scouts per step and
        ``fallback_scout`` as scout threshold (few rays: fewer, larger field calls).
    residual_rays: with guide "raster", the rays the band cannot take (close passing
        rays, grazing hits, hits behind a close edge, failed bands) are rendered from
        the mesh's distance sampled every ``residual_step`` β along the ray plus the
        field's residual, interpolated between three evaluations at the
        ``residual_spread``, 1/2 and 1 - ``residual_spread`` quantiles of the ray's
        estimated weights (:mod:`texvocab.render.residual`); the rays it cannot resolve
        are marched: those whose residuals (with the probe's) differ by more than
        ``residual_tolerance`` β, or whose final weights centre outside the three. False
        marches them all. A smaller step integrates the curved SDF more finely (more
        mesh queries; still three field evaluations per ray); a smaller spread puts the
        outer evaluations farther out; a smaller tolerance marches more rays.
    band_newton: with guide "raster", band rays take two evaluations after their probe
        (at the Newton point t* and ``band_spacing`` β / cos behind it) and the SDF
        between is the hit face's plane plus the interpolated residual
        (:func:`texvocab.render.residual.newton_band`, 3 evaluations per ray); False:
        ``band_samples`` samples around t* (1 + band_samples evaluations).
    """

    shell_width: float = 0.04
    shell_voxel: float = 0.01
    shell_exact: bool = True
    skip_empty: bool = True
    coarse_samples: int = 18
    max_coarse: int = 512
    fine_samples: int = 8
    dilate: bool = True
    scout_threshold: float | None = 1e-3
    segment: int = 2
    early_stop_eps: float = 1e-3
    empty_opacity: float = 1e-3
    chunk_rays: int = 4096
    chunk_points: int = 1 << 18
    guide: str = "shell"
    band_samples: int = 4
    band_spacing: float = 2.0
    band_leftover: float = 0.1
    min_cos: float = 0.25
    miss_margin: float = 8.0
    fallback_segment: int = 8
    fallback_scout: float | None = 1e-3
    residual_rays: bool = True
    residual_step: float = 1.5
    residual_spread: float = 0.05
    residual_tolerance: float = 2.0
    band_newton: bool = True


GUIDES = ("raster", "shell")


class RenderCancelled(Exception):
    """Raised inside :func:`render_image` when its ``cancelled()`` callback returns True."""


@dataclass
class RayResult:
    """rgb (R, 3) over the background; opacity (R,); depth (R,): expected ray distance of
    the surface, sum(w t) / opacity (0 for empty rays); field_evals: points evaluated;
    banded: rays resolved by the surface band (:func:`texvocab.render.band.render_rays_banded`);
    residual: rays resolved as residual rays there.
    """

    rgb: torch.Tensor
    opacity: torch.Tensor
    depth: torch.Tensor
    field_evals: int
    banded: int = 0
    residual: int = 0


@dataclass
class RenderStats:
    """field_evals: points passed to the field; rays: rays marched (hit the shell);
    pixels: image size; seconds: wall time in total; shell_seconds: of it, building the
    shell geometry (0 when a prebuilt one was passed)."""

    field_evals: int
    rays: int
    pixels: int
    seconds: float
    shell_seconds: float = 0.0


@dataclass
class RenderResult:
    """rgb (H, W, 3), alpha (H, W), depth (H, W) (ray distance, 0 where empty), stats."""

    rgb: torch.Tensor
    alpha: torch.Tensor
    depth: torch.Tensor
    stats: RenderStats


def _on_path(path: ShellPath, u: torch.Tensor) -> RaySamples:
    """Sorted path positions u (R, S) (+inf padding) as samples with Voronoi intervals."""
    starts, ends = midpoint_intervals(u, path.length)
    return RaySamples(u, starts, ends, path.to_t(torch.minimum(u, path.length[:, None])))


def fine_pass(field: Field, path: ShellPath, coarse: RaySamples, sigma_c: torch.Tensor,
              rgb_c: torch.Tensor, weights: torch.Tensor, o: torch.Tensor, d: torch.Tensor,
              s: MarchSettings, generator: torch.Generator | None = None):
    """The importance pass of rays whose coarse pass saw some opacity (F of them).

    ``s.fine_samples`` positions by inverse CDF of the (dilated) coarse ``weights`` (F, N)
    over the coarse bins; the field evaluated there; the sorted union of coarse and fine
    samples composited again. Returns opacity (F,), colour (F, 3), weighted depth (F,)
    (not yet divided by opacity) and the number of field evaluations.
    """
    edges = torch.cat([coarse.starts, coarse.ends[:, -1:]], 1)
    if s.dilate:
        weights = dilate_weights(weights) * (edges[:, 1:] > edges[:, :-1])
    u_f = sample_pdf(edges, weights, s.fine_samples, generator)
    t_f = path.to_t(u_f)
    d_f = d[:, None].expand(-1, s.fine_samples, -1).reshape(-1, 3)
    sigma_f, rgb_f = evaluate_field(field, (o[:, None] + t_f[..., None] * d[:, None])
                                    .reshape(-1, 3), d_f, s.chunk_points)
    u, order = torch.cat([coarse.u, u_f], 1).sort(1)
    both = _on_path(path, u)
    sigma = torch.cat([sigma_c, sigma_f.view(len(u), -1)], 1).gather(1, order)
    rgb = torch.cat([rgb_c, rgb_f.view(len(u), -1, 3)], 1)
    rgb = rgb.gather(1, order[..., None].expand(-1, -1, 3))
    w, acc, color = composite(sigma, rgb, both.deltas)
    return acc, color, (w * both.t).sum(1), len(sigma_f)


def render_rays(field: Field, origins: torch.Tensor, dirs: torch.Tensor, near: torch.Tensor,
                far: torch.Tensor, settings: MarchSettings | None = None,
                generator: torch.Generator | None = None, shell: ShellGeometry | None = None,
                background=(0.0, 0.0, 0.0)) -> RayResult:
    """Volume-render rays; differentiable w.r.t. the field's outputs.

    Steps: the in-shell path of each ray (:func:`trace_path`); coarse samples every
    2δ / coarse_samples along it, marched front to back with scouting and early
    termination (:func:`coarse_pass`); for rays with some opacity, ``fine_samples`` by
    inverse CDF of the (dilated) coarse weights; the sorted union composited with
    Voronoi intervals (:func:`composite`); a stopped ray's leftover transmittance goes
    to its last evaluated sample (:func:`absorb`); then the background.

    Args:
        origins, dirs: (R, 3) world rays, dirs unit. near, far: (R,) ray distances (from
            :meth:`ShellGeometry.image_bounds` or :meth:`ShellGeometry.ray_bounds`);
            rays with far <= near cost nothing and return the background.
        shell: the posed mesh's :class:`ShellGeometry`; with ``settings.skip_empty``
            samples go only to the in-shell path. None: uniform over [near, far].
        generator: None for deterministic samples (bin midpoints, fixed quantiles);
            a torch.Generator for stratified jitter and random importance samples.
        background: RGB the rays are composited over.
    """
    s = settings or MarchSettings()
    R = len(origins)
    bg = torch.as_tensor(background, dtype=origins.dtype)
    path = trace_path(shell if s.skip_empty else None, origins, dirs, near, far)
    live = torch.nonzero(path.length > 0).squeeze(1)
    if len(live) == 0:
        return RayResult(bg.repeat(R, 1), origins.new_zeros(R), origins.new_zeros(R), 0)
    o, d = origins[live], dirs[live]
    path = path.rows(live)
    step = 2 * (shell.width if shell is not None else s.shell_width) / s.coarse_samples
    u_c, _ = stratified_positions(path.length, step, s.max_coarse, generator)
    coarse = _on_path(path, u_c)
    marched = coarse_pass(field, coarse, path.length, o, d, s.early_stop_eps, s.segment,
                          s.chunk_points, s.scout_threshold)
    coarse, sigma_c, rgb_c, evals = marched.samples, marched.sigma, marched.rgb, marched.evals
    w_c, acc, color = composite(sigma_c, rgb_c, coarse.deltas)
    depth = (w_c * coarse.t).sum(1)
    fine = torch.nonzero(acc.detach() >= max(s.empty_opacity, 1e-12)).squeeze(1)
    if s.fine_samples > 0 and len(fine):
        acc_f, color_f, depth_f, n = fine_pass(field, path.rows(fine), coarse.rows(fine),
                                               sigma_c[fine], rgb_c[fine], w_c[fine].detach(),
                                               o[fine], d[fine], s, generator)
        evals += n
        acc = acc.index_put((fine,), acc_f)
        color = color.index_put((fine,), color_f)
        depth = depth.index_put((fine,), depth_f)
    acc, color, depth = absorb(marched, acc, color, depth)
    rgb_live = color + (1 - acc)[:, None] * bg
    return RayResult(bg.repeat(R, 1).index_put((live,), rgb_live),
                     origins.new_zeros(R).index_put((live,), acc),
                     origins.new_zeros(R).index_put((live,), depth / acc.clamp(min=1e-6)),
                     evals)


def render_image(field: Field, camera, vertices, faces, settings: MarchSettings | None = None,
                 background=(0.0, 0.0, 0.0), shell: ShellGeometry | None = None,
                 generator: torch.Generator | None = None,
                 cancelled: Callable[[], bool] | None = None, index=None) -> RenderResult:
    """Render one image of the field around the posed mesh (vertices (V, 3), faces (F, 3)).

    Pass a prebuilt ``shell`` (:meth:`ShellGeometry.build` of the same mesh) to reuse the
    per-pose work across images; it then overrides settings.shell_width/shell_voxel.
    ``cancelled`` is checked between ray chunks; when it returns True,
    :class:`RenderCancelled` is raised. ``index``: the mesh's SurfaceIndex, which the
    surface-guided marcher uses for its passing rays (built when needed if not given).
    Differentiable w.r.t. the field's outputs (the shell marcher's).
    """
    s = settings or MarchSettings()
    if s.guide not in GUIDES:
        raise ValueError(f"MarchSettings.guide={s.guide!r}: expected one of {GUIDES}")
    if s.guide == "raster":
        from texvocab.render.guided import render_image_guided  # it builds on this module

        return render_image_guided(field, camera, vertices, faces, s, background, cancelled, shell,
                                   index)
    start = time.perf_counter()
    shell_seconds = 0.0
    if shell is None:
        shell = ShellGeometry.build(vertices, faces, s.shell_width, s.shell_voxel,
                                    s.shell_exact)
        shell_seconds = time.perf_counter() - start
    H, W = camera.height, camera.width
    bounds = shell.image_bounds(camera)
    pix = torch.nonzero(bounds.hit.view(-1)).squeeze(1)
    origins, dirs = camera.pixel_rays(torch.stack([pix % W, pix // W], 1).numpy())
    near, far = bounds.near.view(-1)[pix], bounds.far.view(-1)[pix]
    parts = []
    for c in range(0, len(pix), s.chunk_rays):
        if cancelled is not None and cancelled():
            raise RenderCancelled
        sl = slice(c, c + s.chunk_rays)
        parts.append(render_rays(field, origins[sl], dirs[sl], near[sl], far[sl], s,
                                 generator, shell, background))
    bg = torch.as_tensor(background, dtype=torch.float32)
    rgb, alpha, depth = bg.repeat(H * W, 1), torch.zeros(H * W), torch.zeros(H * W)
    if parts:
        rgb = rgb.index_put((pix,), torch.cat([p.rgb for p in parts]))
        alpha = alpha.index_put((pix,), torch.cat([p.opacity for p in parts]))
        depth = depth.index_put((pix,), torch.cat([p.depth for p in parts]))
    stats = RenderStats(sum(p.field_evals for p in parts), len(pix), H * W,
                        time.perf_counter() - start, shell_seconds)
    return RenderResult(rgb.reshape(H, W, 3), alpha.view(H, W), depth.view(H, W), stats)
