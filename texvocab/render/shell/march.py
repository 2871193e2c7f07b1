"""The shell marcher: coarse-to-fine ray marching inside the thin shell around the posed
body, the NeRF volume rendering of TexVocab's "Preliminary" (Eq. 1 field; "following NeRF,
we render the images using output density values and color values"), the density coming
from the field's SDF via VolSDF ("Training" section).

The marcher takes the field as a callback (:mod:`texvocab.render.volume.field`) and knows
nothing of the network or the vocabulary. Per image: rays that miss the δ-shell are never
generated (:meth:`ShellGeometry.image_bounds`); along the others only the in-shell path counts
(:func:`trace_path`), so gaps between limbs and empty space cost no field evaluations.
Per ray: stratified coarse samples every 2δ / ``shell.coarse_samples`` metres of in-shell
path, evaluated front to back with early termination (:func:`march_until_opaque`) and
every other one only where the field shows density (:func:`coarse_pass`); then
``shell.fine_samples`` drawn by inverse-CDF sampling of the (dilated) coarse weights
(:func:`sample_pdf`); the union of both composited over the background.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import torch

from texvocab.render.results import RayResult, RenderCancelled, RenderResult, RenderStats
from texvocab.render.settings import MarchSettings
from texvocab.render.shell.coarse import absorb, coarse_pass
from texvocab.render.shell.geometry import ShellGeometry
from texvocab.render.shell.path import ShellPath, trace_path
from texvocab.render.volume.field import Field, evaluate_field
from texvocab.render.volume.samples import (
    RaySamples,
    composite,
    dilate_weights,
    midpoint_intervals,
    sample_pdf,
    stratified_positions,
)


def _on_path(path: ShellPath, u: torch.Tensor) -> RaySamples:
    """Sorted path positions u (R, S) (+inf padding) as samples with Voronoi intervals."""
    starts, ends = midpoint_intervals(u, path.length)
    return RaySamples(u, starts, ends, path.to_t(torch.minimum(u, path.length[:, None])))


def fine_pass(
    field: Field,
    path: ShellPath,
    coarse: RaySamples,
    sigma_c: torch.Tensor,
    rgb_c: torch.Tensor,
    weights: torch.Tensor,
    o: torch.Tensor,
    d: torch.Tensor,
    s: MarchSettings,
    generator: torch.Generator | None = None,
):
    """The importance pass of rays whose coarse pass saw some opacity (F of them).

    ``shell.fine_samples`` positions by inverse CDF of the (dilated) coarse ``weights`` (F, N)
    over the coarse bins; the field evaluated there; the sorted union of coarse and fine
    samples composited again. Returns opacity (F,), colour (F, 3), weighted depth (F,)
    (not yet divided by opacity) and the number of field evaluations.
    """
    edges = torch.cat([coarse.starts, coarse.ends[:, -1:]], 1)
    if s.shell.dilate:
        weights = dilate_weights(weights) * (edges[:, 1:] > edges[:, :-1])
    u_f = sample_pdf(edges, weights, s.shell.fine_samples, generator)
    t_f = path.to_t(u_f)
    d_f = d[:, None].expand(-1, s.shell.fine_samples, -1).reshape(-1, 3)
    sigma_f, rgb_f = evaluate_field(
        field, (o[:, None] + t_f[..., None] * d[:, None]).reshape(-1, 3), d_f, s.chunks.points
    )
    u, order = torch.cat([coarse.u, u_f], 1).sort(1)
    both = _on_path(path, u)
    sigma = torch.cat([sigma_c, sigma_f.view(len(u), -1)], 1).gather(1, order)
    rgb = torch.cat([rgb_c, rgb_f.view(len(u), -1, 3)], 1)
    rgb = rgb.gather(1, order[..., None].expand(-1, -1, 3))
    w, acc, color = composite(sigma, rgb, both.deltas)
    return acc, color, (w * both.t).sum(1), len(sigma_f)


def render_rays(
    field: Field,
    origins: torch.Tensor,
    dirs: torch.Tensor,
    near: torch.Tensor,
    far: torch.Tensor,
    settings: MarchSettings | None = None,
    generator: torch.Generator | None = None,
    shell: ShellGeometry | None = None,
    background=(0.0, 0.0, 0.0),
) -> RayResult:
    """Volume-render rays; differentiable w.r.t. the field's outputs.

    Steps: the in-shell path of each ray (:func:`trace_path`); coarse samples every
    2δ / ``shell.coarse_samples`` along it, marched front to back with scouting and early
    termination (:func:`coarse_pass`); for rays with some opacity, ``shell.fine_samples`` by
    inverse CDF of the (dilated) coarse weights; the sorted union composited with
    Voronoi intervals (:func:`composite`); a stopped ray's leftover transmittance goes
    to its last evaluated sample (:func:`absorb`); then the background.

    Args:
        origins, dirs: (R, 3) world rays, dirs unit. near, far: (R,) ray distances (from
            :meth:`ShellGeometry.image_bounds` or :meth:`ShellGeometry.ray_bounds`);
            rays with far <= near cost nothing and return the background.
        shell: the posed mesh's :class:`ShellGeometry`; with ``settings.shell.skip_empty``
            samples go only to the in-shell path. None: uniform over [near, far].
        generator: None for deterministic samples (bin midpoints, fixed quantiles);
            a torch.Generator for stratified jitter and random importance samples.
        background: RGB the rays are composited over.
    """
    s = settings or MarchSettings()
    R = len(origins)
    bg = torch.as_tensor(background, dtype=origins.dtype)
    path = trace_path(shell if s.shell.skip_empty else None, origins, dirs, near, far)
    live = torch.nonzero(path.length > 0).squeeze(1)
    if len(live) == 0:
        return RayResult(bg.repeat(R, 1), origins.new_zeros(R), origins.new_zeros(R), 0)
    o, d = origins[live], dirs[live]
    path = path.rows(live)
    step = 2 * (shell.width if shell is not None else s.shell.width) / s.shell.coarse_samples
    u_c, _ = stratified_positions(path.length, step, s.shell.max_coarse, generator)
    coarse = _on_path(path, u_c)
    marched = coarse_pass(
        field,
        coarse,
        path.length,
        o,
        d,
        s.shell.early_stop_eps,
        s.shell.segment,
        s.chunks.points,
        s.shell.scout_threshold,
    )
    coarse, sigma_c, rgb_c, evals = marched.samples, marched.sigma, marched.rgb, marched.evals
    w_c, acc, color = composite(sigma_c, rgb_c, coarse.deltas)
    depth = (w_c * coarse.t).sum(1)
    fine = torch.nonzero(acc.detach() >= max(s.shell.empty_opacity, 1e-12)).squeeze(1)
    if s.shell.fine_samples > 0 and len(fine):
        acc_f, color_f, depth_f, n = fine_pass(
            field,
            path.rows(fine),
            coarse.rows(fine),
            sigma_c[fine],
            rgb_c[fine],
            w_c[fine].detach(),
            o[fine],
            d[fine],
            s,
            generator,
        )
        evals += n
        acc = acc.index_put((fine,), acc_f)
        color = color.index_put((fine,), color_f)
        depth = depth.index_put((fine,), depth_f)
    acc, color, depth = absorb(marched, acc, color, depth)
    rgb_live = color + (1 - acc)[:, None] * bg
    return RayResult(
        bg.repeat(R, 1).index_put((live,), rgb_live),
        origins.new_zeros(R).index_put((live,), acc),
        origins.new_zeros(R).index_put((live,), depth / acc.clamp(min=1e-6)),
        evals,
    )


def build_shell(settings: MarchSettings, vertices, faces, index=None) -> ShellGeometry:
    """The shell geometry of a posed mesh (V, 3), (F, 3) with the shell group's width, voxel
    and exactness (``index``: the mesh's SurfaceIndex, built when needed if not given)."""
    s = settings.shell
    return ShellGeometry.build(vertices, faces, s.width, s.voxel, s.exact, index=index)


def march_chunks(
    field: Field,
    origins: torch.Tensor,
    dirs: torch.Tensor,
    near: torch.Tensor,
    far: torch.Tensor,
    settings: MarchSettings,
    generator: torch.Generator | None,
    shell: ShellGeometry | None,
    background,
    cancelled: Callable[[], bool] | None = None,
) -> RayResult:
    """:func:`render_rays` over ``chunks.rays`` rays at a time (memory), checking
    ``cancelled`` before each chunk (:class:`RenderCancelled`)."""
    parts = []
    for c in range(0, len(origins), settings.chunks.rays):
        if cancelled is not None and cancelled():
            raise RenderCancelled
        sl = slice(c, c + settings.chunks.rays)
        parts.append(
            render_rays(
                field, origins[sl], dirs[sl], near[sl], far[sl], settings, generator, shell, background
            )
        )
    if not parts:
        z = origins.new_zeros(0)
        return RayResult(origins.new_zeros(0, 3), z, z.clone(), 0)
    return RayResult(
        torch.cat([p.rgb for p in parts]),
        torch.cat([p.opacity for p in parts]),
        torch.cat([p.depth for p in parts]),
        sum(p.field_evals for p in parts),
    )


def render_image_shell(
    field: Field,
    camera,
    vertices,
    faces,
    settings: MarchSettings | None = None,
    background=(0.0, 0.0, 0.0),
    shell: ShellGeometry | None = None,
    generator: torch.Generator | None = None,
    cancelled: Callable[[], bool] | None = None,
    index=None,
) -> RenderResult:
    """Render one image of the field around the posed mesh (vertices (V, 3), faces (F, 3))
    with the shell marcher, ``chunks.rays`` rays at a time.

    Pass a prebuilt ``shell`` (:func:`build_shell` of the same mesh) to reuse the per-pose
    work across images; it then overrides the shell group's width and voxel. ``cancelled``
    is checked between ray chunks (:class:`RenderCancelled`); ``index`` is not used (the
    render paths share one signature). Differentiable w.r.t. the field's outputs.
    """
    s = settings or MarchSettings()
    start = time.perf_counter()
    shell_seconds = 0.0
    if shell is None:
        shell = build_shell(s, vertices, faces)
        shell_seconds = time.perf_counter() - start
    H, W = camera.height, camera.width
    bounds = shell.image_bounds(camera)
    pix = torch.nonzero(bounds.hit.view(-1)).squeeze(1)
    origins, dirs = camera.pixel_rays(torch.stack([pix % W, pix // W], 1).numpy())
    near, far = bounds.near.view(-1)[pix], bounds.far.view(-1)[pix]
    out = march_chunks(field, origins, dirs, near, far, s, generator, shell, background, cancelled)
    bg = torch.as_tensor(background, dtype=torch.float32)
    rgb, alpha, depth = bg.repeat(H * W, 1), torch.zeros(H * W), torch.zeros(H * W)
    if len(pix):
        rgb = rgb.index_put((pix,), out.rgb)
        alpha = alpha.index_put((pix,), out.opacity)
        depth = depth.index_put((pix,), out.depth)
    stats = RenderStats(out.field_evals, len(pix), H * W, time.perf_counter() - start, shell_seconds)
    return RenderResult(rgb.reshape(H, W, 3), alpha.view(H, W), depth.view(H, W), stats)


def shell_levels(
    field: Field,
    camera,
    vertices,
    faces,
    s: MarchSettings,
    levels,
    cancelled: Callable[[], bool],
    background,
    shell: ShellGeometry | None,
    index=None,
    shard=(0, 1),
) -> Iterator[tuple[int, torch.Tensor, float, torch.Tensor]]:
    """The shell marcher's progressive levels (:mod:`texvocab.render.progressive`): each a
    render of ``camera.scaled(1 / level)``, the shell built once for all. Not split: shard
    0 renders the whole view, the others yield empty images that own no pixel."""
    if shard[0] > 0:
        for level in levels:
            scaled = camera.scaled(1.0 / level)
            h, w = scaled.height, scaled.width
            yield level, torch.zeros(h, w, 3), 0.0, torch.zeros(h, w, dtype=torch.bool)
        return
    start = time.perf_counter()
    if shell is None:
        shell = build_shell(s, vertices, faces)
    for level in levels:
        if cancelled():
            return
        try:
            with torch.no_grad():  # not held across the yield: the caller keeps autograd
                result = render_image_shell(
                    field,
                    camera.scaled(1.0 / level),
                    vertices,
                    faces,
                    s,
                    background,
                    shell=shell,
                    cancelled=cancelled,
                )
        except RenderCancelled:
            return
        yield (
            level,
            result.rgb,
            time.perf_counter() - start,
            torch.ones(result.rgb.shape[:2], dtype=torch.bool),
        )
        start = time.perf_counter()
