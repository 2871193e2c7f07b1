"""The triage of rays by the surface-guided marcher: the one function that decides how each
ray is rendered — for images (:class:`~texvocab.render.guided.image.GuidedImage`) and for
training (:func:`render_rays_banded`) — and counts what it costs (the points passed to the
field, counted by the stage that evaluates them).

Per ray, in order (:mod:`texvocab.render.guided` says why each step holds):

1. **probes**: a ray that passes a nearer surface (finite ``t_passing``) gets two where it
   comes closest to it, and a mesh hit that a band or a residual ray may start from (a
   cosine >= ``band.min_cos``, or any hit with ``residual.enabled``) gets one at t_hit. The
   passed surface is *close* when a passing probe reads an SDF within ``band.miss_margin``
   β.
2. **background** (:attr:`RayKind.BACKGROUND`): misses whose passed surface is not close.
3. **band** (:attr:`RayKind.BAND`): probed hits at a cosine >= ``band.min_cos`` with no
   close passed surface (:func:`~texvocab.render.guided.band.newton_band` with
   ``band.newton``, else :func:`~texvocab.render.guided.band.sample_band`).
4. **residual rays** (:attr:`RayKind.RESIDUAL`; ``residual.enabled`` and a mesh
   ``index``): the rays left that have a probe (hits only, unless ``residual_misses``),
   :func:`~texvocab.render.guided.residual.render_residual`.
5. **fallback** (:attr:`RayKind.FALLBACK`): the rest, marched by the caller's ``march``.

Rendering (``differentiable=False``) evaluates every probe in one field call, the hits of
rays found close included (the residual rays start from them). Training
(``differentiable=True``) evaluates the passing probes first, without gradient, and then
the hit probes of the rays that are not close, with gradient: the band composites them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch

from texvocab.geometry.surface import SurfaceIndex
from texvocab.render.guided.band import newton_band, sample_band
from texvocab.render.guided.residual import render_residual
from texvocab.render.results import RayKind, RayResult, RenderCancelled
from texvocab.render.settings import MarchSettings
from texvocab.render.shell.geometry import ShellGeometry
from texvocab.render.shell.march import render_rays
from texvocab.render.volume.field import evaluate_sdf, points_along
from texvocab.render.volume.volsdf import beta_value


@dataclass
class GuidedRays:
    """R rays as the surface plan sees them. origins: (R, 3), or one origin (3,) for all;
    dirs: (R, 3) unit; t_hit: (R,) ray distance of the mesh hit a probe may start from (inf:
    none); cos: (R,) |cosine| between the ray and the hit face's normal; t_passing: (R, 2)
    the two probe distances of rays that pass a nearer surface (inf: not passing), or
    None; face: (R,) long the mesh face hit at t_hit (-1: none), or None (not known: the
    field searches the hit probes' closest faces)."""

    origins: torch.Tensor
    dirs: torch.Tensor
    t_hit: torch.Tensor
    cos: torch.Tensor
    t_passing: torch.Tensor | None = None
    face: torch.Tensor | None = None

    def origins_of(self, idx: torch.Tensor) -> torch.Tensor:
        """The origins of rays idx (n,): (n, 3), or the shared (3,)."""
        return self.origins if self.origins.dim() == 1 else self.origins[idx]


@dataclass
class _Probes:
    """Step 1's outcome: ``close`` (R,) bool; the hit probes' rays ``h_idx`` (H,) and their
    SDF ``sdf_h`` (H,) and colour ``rgb_h`` (H, 3); each ray's probe distances ``t`` and
    SDFs ``sdf`` (R, 3) (passing, behind, hit; inf where none) for the residual rays, and
    the probes' known closest faces ``face`` (R, 3) (-1: unknown), or None."""

    close: torch.Tensor
    h_idx: torch.Tensor
    sdf_h: torch.Tensor
    rgb_h: torch.Tensor
    t: torch.Tensor
    sdf: torch.Tensor
    evals: int
    face: torch.Tensor | None = None


def _probe(
    field, rays: GuidedRays, probed: torch.Tensor, s: MarchSettings, beta: float, differentiable: bool
) -> _Probes:
    """Step 1 of the module docstring."""
    R, dirs, chunk = len(rays.dirs), rays.dirs, s.chunks.points
    t_pass = rays.t_passing if rays.t_passing is not None else dirs.new_full((R, 2), torch.inf)
    p_idx = torch.nonzero(torch.isfinite(t_pass[:, 0])).squeeze(1)
    close = torch.zeros(R, dtype=torch.bool)
    if differentiable:
        with torch.no_grad():
            sdf_p, _ = evaluate_sdf(
                field,
                points_along(rays.origins_of(p_idx), dirs[p_idx], t_pass[p_idx]).reshape(-1, 3),
                dirs[p_idx].repeat_interleave(2, 0),
                chunk,
            )
        sdf_p = sdf_p.view(-1, 2)
        close[p_idx] = sdf_p.min(1).values <= s.band.miss_margin * beta
        h_idx = torch.nonzero(probed & ~close).squeeze(1)
        sdf_h, rgb_h = evaluate_sdf(
            field, points_along(rays.origins_of(h_idx), dirs[h_idx], rays.t_hit[h_idx]), dirs[h_idx], chunk
        )
        evals = 2 * len(p_idx) + len(h_idx)
    else:
        h_idx = torch.nonzero(probed).squeeze(1)
        idx = torch.cat([p_idx, p_idx, h_idx])
        t = torch.cat([t_pass[p_idx, 0], t_pass[p_idx, 1], rays.t_hit[h_idx]])
        known = None  # a hit probe lies on its hit face
        if rays.face is not None:
            known = torch.cat([p_idx.new_full((2 * len(p_idx),), -1), rays.face[h_idx]])
        sdf, rgb = evaluate_sdf(
            field, points_along(rays.origins_of(idx), dirs[idx], t), dirs[idx], chunk, known
        )
        n = len(p_idx)
        sdf_p = torch.stack([sdf[:n], sdf[n : 2 * n]], 1)
        close[p_idx] = torch.minimum(sdf[:n], sdf[n : 2 * n]) <= s.band.miss_margin * beta
        sdf_h, rgb_h = sdf[2 * n :], rgb[2 * n :]
        evals = len(idx)
    probe_t = dirs.new_full((R, 3), torch.inf)
    probe_sdf = dirs.new_full((R, 3), torch.inf)
    probe_t[p_idx, :2], probe_sdf[p_idx, :2] = t_pass[p_idx], sdf_p.detach()
    probe_t[h_idx, 2], probe_sdf[h_idx, 2] = rays.t_hit[h_idx], sdf_h.detach()
    probe_face = None
    if rays.face is not None:
        probe_face = torch.full((R, 3), -1, dtype=torch.long)
        probe_face[h_idx, 2] = rays.face[h_idx]
    return _Probes(close, h_idx, sdf_h, rgb_h, probe_t, probe_sdf, evals, probe_face)


def triage_rays(
    field,
    beta,
    rays: GuidedRays,
    settings: MarchSettings,
    *,
    march: Callable[[torch.Tensor], RayResult] | None,
    bounds: Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor]],
    index: Callable[[], SurfaceIndex] | None = None,
    background=(0.0, 0.0, 0.0),
    differentiable: bool = False,
    residual_misses: bool = True,
    cancelled: Callable[[], bool] | None = None,
) -> RayResult:
    """Render ``rays`` by the steps of the module docstring.

    ``field``: ``sdf_rgb(points, dirs) -> (sdf, rgb)`` (and the marcher's call for
    ``march``); ``beta``: its VolSDF β, a float or the model's β tensor (training). The
    caller supplies, each called only when some ray needs it: ``march(idx)``, the shell
    marcher's :class:`RayResult` of rays idx (n,) (None: those rays are left unrendered —
    :attr:`RayKind.NONE`, shown with their hit probe's colour, else the background: a
    preview — and no residual rays are tried); ``bounds(idx)``, their shell interval (near,
    far) (n,); ``index()``, the posed mesh's SurfaceIndex (None: no residual rays).
    ``cancelled`` is checked before each stage (:class:`RenderCancelled`).

    Returns rgb over ``background``, opacity, depth (R,), the field evaluations and each
    ray's :class:`RayKind` (R,). Differentiable w.r.t. the field's outputs and β when
    ``differentiable`` (the probes of passing rays, the sample places and the triage itself
    carry no gradient).
    """
    s, R = settings, len(rays.dirs)

    def check() -> None:
        if cancelled is not None and cancelled():
            raise RenderCancelled

    b = beta_value(beta)
    bg = torch.as_tensor(background, dtype=rays.dirs.dtype)
    hit, cos = torch.isfinite(rays.t_hit), rays.cos
    check()
    probes = _probe(field, rays, hit & ((cos >= s.band.min_cos) | s.residual.enabled), s, b, differentiable)
    evals = probes.evals
    kind = torch.zeros(R, dtype=torch.uint8)
    passing = torch.isfinite(probes.t[:, 0])
    kind[passing & ~probes.close & ~hit] = RayKind.BACKGROUND
    alone = cos[probes.h_idx] >= s.band.min_cos
    if not differentiable:  # the hits of close rays were probed too
        alone &= ~probes.close[probes.h_idx]
    b_idx = probes.h_idx[alone]
    band = newton_band if s.band.newton else sample_band
    acc, color, depth, ok, n = band(
        field,
        rays.origins_of(b_idx),
        rays.dirs[b_idx],
        rays.t_hit[b_idx],
        cos[b_idx],
        probes.sdf_h[alone],
        probes.rgb_h[alone],
        beta,
        s,
    )
    evals += n
    kind[b_idx[ok]] = RayKind.BAND
    out = _Rows(R, bg)
    out.put(b_idx[ok], color[ok] + (1 - acc[ok])[:, None] * bg, acc[ok], depth[ok])
    left = kind == RayKind.NONE
    if march is None:  # a preview: the rest shows the colour at its mesh hit
        shown = left[probes.h_idx]
        z = bg.new_zeros(int(shown.sum()))
        out.put(probes.h_idx[shown], probes.rgb_h[shown], z, z)
        return out.result(evals, kind)
    take = left & torch.isfinite(probes.sdf).any(1)
    if not residual_misses:
        take &= hit
    r_idx = torch.nonzero(take).squeeze(1)
    if index is not None and s.residual.enabled and len(r_idx):
        check()
        near, far = bounds(r_idx)
        acc, color, depth, ok, n = render_residual(
            field,
            index(),
            rays.origins_of(r_idx),
            rays.dirs[r_idx],
            near,
            far,
            probes.t[r_idx],
            probes.sdf[r_idx],
            beta,
            s,
            None if probes.face is None else probes.face[r_idx],
        )
        evals += n
        kind[r_idx[ok]] = RayKind.RESIDUAL
        out.put(r_idx[ok], color[ok] + (1 - acc[ok])[:, None] * bg, acc[ok], depth[ok])
    m_idx = torch.nonzero(kind == RayKind.NONE).squeeze(1)
    kind[m_idx] = RayKind.FALLBACK
    if len(m_idx):
        check()
        rest = march(m_idx)
        out.put(m_idx, rest.rgb, rest.opacity, rest.depth)
        evals += rest.field_evals
    return out.result(evals, kind)


class _Rows:
    """The triage's output for R rays, filled by rows: rgb (R, 3) (the background until
    put), opacity (R,), depth (R,); out of place, so gradients reach every stage."""

    def __init__(self, R: int, bg: torch.Tensor):
        self.rgb, self.opacity, self.depth = bg.repeat(R, 1), bg.new_zeros(R), bg.new_zeros(R)

    def put(self, rows: torch.Tensor, rgb: torch.Tensor, opacity: torch.Tensor, depth: torch.Tensor) -> None:
        self.rgb = self.rgb.index_put((rows,), rgb)
        self.opacity = self.opacity.index_put((rows,), opacity)
        self.depth = self.depth.index_put((rows,), depth)

    def result(self, evals: int, kind: torch.Tensor) -> RayResult:
        return RayResult(self.rgb, self.opacity, self.depth, evals, kind)


def render_rays_banded(
    field,
    beta,
    origins: torch.Tensor,
    dirs: torch.Tensor,
    near: torch.Tensor,
    far: torch.Tensor,
    t_hit: torch.Tensor,
    cos: torch.Tensor,
    settings: MarchSettings,
    generator: torch.Generator | None = None,
    shell: ShellGeometry | None = None,
    background=(0.0, 0.0, 0.0),
    t_passing: torch.Tensor | None = None,
    index: SurfaceIndex | None = None,
    residual_misses: bool = True,
) -> RayResult:
    """Training's rays (R,): :func:`triage_rays`, differentiable, with the shell marcher
    (:func:`~texvocab.render.shell.march.render_rays` with ``settings``, ``generator`` and
    ``shell``) over [near, far] (R,) for the rays the band and the residual rays leave.

    origins, dirs: (R, 3); t_hit: (R,) the band rays' mesh hit (inf elsewhere) at ``cos``
    (R,) >= ``band.min_cos``; t_passing: (R, 2) the probe places of rays that pass a nearer
    surface (inf elsewhere); index: the posed mesh's SurfaceIndex for the residual rays
    (None: none); residual_misses: close passing misses are residual rays too (else
    marched). Returns a :class:`RayResult` (``banded``, ``residual``: rays of each kind)."""

    def march(idx: torch.Tensor) -> RayResult:
        return render_rays(
            field, origins[idx], dirs[idx], near[idx], far[idx], settings, generator, shell, background
        )

    return triage_rays(
        field,
        beta,
        GuidedRays(origins, dirs, t_hit, cos, t_passing),
        settings,
        march=march,
        bounds=lambda idx: (near[idx], far[idx]),
        index=None if index is None else (lambda: index),
        background=background,
        differentiable=True,
        residual_misses=residual_misses,
    )
