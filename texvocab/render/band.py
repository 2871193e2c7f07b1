"""The surface band: where the posed mesh's rasterisation puts each ray's surface, and a
few samples around it composited with the VolSDF opacity integrated in closed form.
Shared by the surface-guided image renderer (:mod:`texvocab.render.guided`) and training
(:func:`render_rays_banded`), and differentiable w.r.t. the field's outputs and β.

The avatar's SDF is the posed body's signed distance plus a residual, and its density is
zero beyond the shell (δ from the mesh), so a ray's first surface lies within δ of the
mesh's first hit. A *band ray* (it hits the mesh at a cosine >= ``min_cos`` and passes no
nearer surface) gets one *probe* evaluation at the mesh hit t_m, giving the SDF s_0; the
surface is at t* ≈ t_m + s_0 / cos (one Newton step along the ray with the face's
cosine); ``band_samples`` samples spaced ``band_spacing`` β / cos around t* are evaluated
in one call. Between samples the SDF is taken linear and the VolSDF optical depth of each
interval is exact for it (:func:`interval_optical_depth`): with β ≈ 2 mm a handful of
samples integrate the opacity profile that a Riemann sum needs dozens for. A ray whose
samples do not bracket the surface (first SDF > 0 > last) or leave more than
``band_leftover`` transmittance is not resolved by the band (the callers march it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from scipy import ndimage

from texvocab.geometry.raster import rasterize_mesh
from texvocab.render.coarse import evaluate_field

_FAR = 1e6  # stands for "no surface" in the min/max filters (metres)


def laplace_antiderivative(s: torch.Tensor, beta) -> torch.Tensor:
    """F(s) = ∫ Ψ_β(-s) ds with F(+∞) = 0: -β/2 e^(-s/β) for s >= 0, s - β/2 e^(s/β) below
    (Ψ_β the Laplace CDF of VolSDF's density σ = Ψ_β(-s) / β). β: float or 0-d tensor."""
    e = torch.exp(-s.abs() / beta)
    return torch.where(s >= 0, -0.5 * beta * e, s - 0.5 * beta * e)


def interval_optical_depth(s_a: torch.Tensor, s_b: torch.Tensor, length: torch.Tensor,
                           beta) -> torch.Tensor:
    """∫ σ dt over an interval of ``length`` where the SDF runs linearly from s_a to s_b:
    length (F(s_a) - F(s_b)) / (β (s_a - s_b)); the density at the mean SDF times the
    length where |s_a - s_b| < 1e-4 β (where the quotient loses precision)."""
    ds = s_a - s_b
    flat = ds.abs() < 1e-4 * beta
    exact = (laplace_antiderivative(s_a, beta) - laplace_antiderivative(s_b, beta)) / \
        torch.where(flat, torch.ones_like(ds), ds)
    mid = 0.5 * (s_a + s_b)
    e = torch.exp(-mid.abs() / beta)  # never overflows (nor does its gradient, where unused)
    density = torch.where(mid >= 0, 0.5 * e, 1 - 0.5 * e)
    return length * torch.where(flat, density, exact) / beta


def composite_linear_sdf(t: torch.Tensor, sdf: torch.Tensor, rgb: torch.Tensor, beta,
                         front: bool = True
                         ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Volume-render rays from sorted samples (R, S) of a piecewise-linear SDF.

    Intervals between samples get their closed-form optical depth and the mean of their
    end colours; the ray in front of the first sample continues the first interval's
    line (σ integrated from s = +∞, the first sample's colour); the transmittance left
    after the last sample goes to the last colour where that sample is inside (SDF < 0:
    the ray ends in the body) and to the background otherwise (it passed by).

    Returns opacity (R,), colour (R, 3) (not over a background), expected depth (R,)
    and the transmittance (R,) left after the last sample. ``front=False`` leaves out
    the part in front of the first sample (where the samples start far enough out that
    it holds no density, but their first interval may be flat).
    """
    weights, ends, rest = linear_sdf_weights(t, sdf, beta, front)
    colours = torch.cat([rgb[:, :1], 0.5 * (rgb[:, 1:] + rgb[:, :-1])], 1)
    places = torch.cat([t[:, :1], 0.5 * (t[:, 1:] + t[:, :-1])], 1)
    color = (weights[..., None] * colours).sum(1) + ends[:, None] * rgb[:, -1]
    acc = weights.sum(1) + ends
    depth = ((weights * places).sum(1) + ends * t[:, -1]) / acc.clamp(min=1e-6)
    return acc, color, depth, rest


def linear_sdf_weights(t: torch.Tensor, sdf: torch.Tensor, beta, front: bool = True
                       ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The quadrature of :func:`composite_linear_sdf`: weights (R, S) of the part in
    front of the first sample (zero when not ``front``) and of each interval between
    samples (t, sdf (R, S)), the weight ``ends`` (R,) the last sample absorbs (the ray
    ends inside) and the transmittance ``rest`` (R,) left after the last sample."""
    dt = (t[:, 1:] - t[:, :-1]).clamp(min=0)
    tau = interval_optical_depth(sdf[:, :-1], sdf[:, 1:], dt, beta)
    if front:
        slope = ((sdf[:, 0] - sdf[:, 1]) / dt[:, 0].clamp(min=1e-9)).clamp(min=1e-3)
        tau_pre = (-laplace_antiderivative(sdf[:, 0], beta) / (beta * slope)).clamp(min=0)
    else:
        tau_pre = torch.zeros_like(t[:, 0])
    taus = torch.cat([tau_pre[:, None], tau], 1)  # (R, S)
    before = torch.cumsum(taus, 1) - taus
    weights = torch.exp(-before) * -torch.expm1(-taus)
    rest = torch.exp(-taus.sum(1))
    ends = (sdf[:, -1] < 0).to(rest.dtype) * rest  # absorbed by the last sample
    return weights, ends, rest


@dataclass
class SurfacePlan:
    """Per pixel (row-major, H·W) of one camera and posed mesh: ``t_hit`` ray distance of
    the mesh's first hit (inf: none), ``cos`` |cosine| between the ray and the hit face's
    normal (0: none), ``passby`` the ray passes a surface nearer than its own hit (more
    than δ nearer, within ``radius`` pixels) or misses the mesh near one; ``t_pass``,
    ``t_behind`` where a passing ray comes closest to the surface it passes (two probe
    distances; inf for other rays); ``band`` the band rays: hit, cos >= min_cos, no
    passby."""

    t_hit: torch.Tensor
    cos: torch.Tensor
    passby: torch.Tensor
    t_pass: torch.Tensor
    t_behind: torch.Tensor
    band: torch.Tensor

    @property
    def hit(self) -> torch.Tensor:
        return torch.isfinite(self.t_hit)


def _frontmost_neighbour(t_map: torch.Tensor, radius: int) -> torch.Tensor:
    """For each pixel of t_map (H, W) (ray distance of the mesh hit, inf where missed):
    the smallest hit distance within its (2 radius + 1)² window (_FAR where none), as a
    separable minimum filter (rows, then columns)."""
    k = 2 * radius + 1
    neg = -torch.where(torch.isfinite(t_map), t_map, _FAR)[None, None]
    neg = F.max_pool2d(F.max_pool2d(neg, (k, 1), 1, (radius, 0)), (1, k), 1, (0, radius))
    return -neg.reshape(-1)


def _frontmost_pixel(t_map: torch.Tensor, radius: int, pix: torch.Tensor) -> torch.Tensor:
    """The flat index of the frontmost hit pixel in the window of each pixel of ``pix``
    (n,) (flat indices into t_map (H, W))."""
    H, W = t_map.shape
    if len(pix) == 0:
        return pix.clone()
    d = torch.arange(-radius, radius + 1)
    y = (pix // W)[:, None, None] + d[None, :, None]
    x = (pix % W)[:, None, None] + d[None, None, :]
    inside = (y >= 0) & (y < H) & (x >= 0) & (x < W)
    flat = (y.clamp(0, H - 1) * W + x.clamp(0, W - 1)).reshape(len(pix), -1)
    t = torch.where(torch.isfinite(t_map), t_map, _FAR).reshape(-1)[flat]
    t = torch.where(inside.reshape(len(pix), -1), t, 2 * _FAR)
    return flat.gather(1, t.argmin(1, keepdim=True)).squeeze(1)


def plan_surface(vertices: torch.Tensor, faces: torch.Tensor, camera, dirs: torch.Tensor,
                 shell_width: float, reach: float, min_cos: float) -> SurfacePlan:
    """The :class:`SurfacePlan` of a posed mesh (V, 3), (F, 3) seen by ``camera`` with
    pixel ray directions dirs (H·W, 3). ``reach``: how far from a ray a passed surface can
    still show (metres; the renderer uses min(δ, miss_margin β), training δ)."""
    H, W = camera.height, camera.width
    raster = rasterize_mesh(vertices, faces, camera)
    along_z = dirs.double() @ torch.as_tensor(camera.R[2], dtype=torch.float64)
    t_hit = (raster.depth.view(-1).double() / along_z).float()
    hit = torch.isfinite(t_hit)
    cos = torch.zeros(H * W)
    none = torch.full((H * W,), torch.inf)
    if not hit.any():
        nothing = torch.zeros(H * W, dtype=torch.bool)
        return SurfacePlan(t_hit, cos, nothing, none, none.clone(), nothing)
    z_min = float(raster.depth.view(-1)[hit].min())
    radius = max(min(int(math.ceil(reach * float(camera.K[0, 0]) / max(z_min, 1e-6))), 64), 1)
    front = _frontmost_neighbour(t_hit.view(H, W), radius)
    tri = vertices.detach().float()[faces]
    normal = F.normalize(torch.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], dim=1),
                         dim=1)
    cos[hit] = (normal[raster.face.view(-1)[hit]] * dirs[hit]).sum(1).abs()
    # rays that pass a surface nearer than their own (or miss the mesh): a neighbour hit
    # nearer by more than δ plus what the hit face's own slope explains
    c = cos.clamp(min=min_cos)
    slope = radius * t_hit / float(camera.K[0, 0]) * (1 - c * c).sqrt() / c
    own = torch.where(hit & (cos >= min_cos), t_hit - slope, t_hit)
    passby = (front < _FAR / 2) & (front < torch.where(hit, own, torch.inf) - shell_width)
    band = hit & (cos >= min_cos) & ~passby
    # A passing ray is probed where it comes closest to the surface it passes: a miss near
    # the nearest hit pixel's surface point, a hit behind an occlusion edge near the
    # nearest surface point of its window. The silhouette's tangent point lies up to a
    # pixel footprint per pixel of distance behind that point, where a second probe looks.
    gap, (iy, ix) = ndimage.distance_transform_edt(~hit.view(H, W).numpy(),
                                                   return_indices=True)
    gap = torch.from_numpy(gap).float().view(-1)
    nearest = torch.from_numpy((iy * W + ix).reshape(-1)).long()
    gap = torch.where(hit, float(radius), gap)
    p_idx = torch.nonzero(passby).squeeze(1)
    behind = hit[p_idx]  # hits behind an occlusion edge: the window's frontmost hit
    nearest[p_idx[behind]] = _frontmost_pixel(t_hit.view(H, W), radius, p_idx[behind])
    q = nearest[p_idx]
    t_pass, t_behind = none, none.clone()
    t_pass[p_idx] = ((t_hit[q, None] * dirs[q]) * dirs[p_idx]).sum(1)
    t_behind[p_idx] = t_pass[p_idx] * (1 + gap[p_idx] / float(camera.K[0, 0]))
    return SurfacePlan(t_hit, cos, passby, t_pass, t_behind, band)


def band_composite(field, s, beta, o: torch.Tensor, d: torch.Tensor, t_hit: torch.Tensor,
                   cos: torch.Tensor, sdf0: torch.Tensor, rgb0: torch.Tensor):
    """Resolve band rays (R,) from their probe: o, d (R, 3) or o (3,), mesh hit t_hit (R,),
    cosine (R,), probe SDF sdf0 (R,) and colour rgb0 (R, 3) at t_hit. Evaluates
    ``s.band_samples`` per ray with ``field.sdf_rgb`` (sample places follow the probe
    but carry no gradient). Returns opacity (R,), colour (R, 3) (not over a background),
    depth (R,) and ok (R,): rays the band resolves (the others must be marched)."""
    if len(t_hit) == 0:
        z = t_hit.new_zeros(0)
        return z, t_hit.new_zeros(0, 3), z, torch.zeros(0, dtype=torch.bool)
    delta = float(s.shell_width)
    step = sdf0.detach() / cos  # Newton step along the ray with the face's cosine
    t_star = t_hit + step.clamp(-delta, delta)
    k = torch.arange(s.band_samples, dtype=torch.float32) - (s.band_samples - 1) / 2
    t_band = t_star[:, None] + k * (s.band_spacing * beta_value(beta)) / cos[:, None]  # (R, B)
    o = o[:, None] if o.dim() == 2 else o
    sdf_b, rgb_b = evaluate_sdf(field, (o + t_band[..., None] * d[:, None]).reshape(-1, 3),
                                d.repeat_interleave(s.band_samples, 0), s.chunk_points)
    t_all, order = torch.cat([t_hit[:, None], t_band], 1).sort(1)
    sdf_all = torch.cat([sdf0[:, None], sdf_b.view(len(t_hit), -1)], 1).gather(1, order)
    rgb_all = torch.cat([rgb0[:, None], rgb_b.view(len(t_hit), -1, 3)], 1)
    rgb_all = rgb_all.gather(1, order[..., None].expand(-1, -1, 3))
    acc, color, depth, rest = composite_linear_sdf(t_all, sdf_all, rgb_all, beta)
    ok = (step.abs() <= delta) & (sdf_all[:, 0] > 0) & (sdf_all[:, -1] < 0) & \
        (rest <= s.band_leftover)
    return acc, color, depth, ok.detach()


def beta_value(beta) -> float:
    """β as a float (a tensor's value without its gradient)."""
    return float(beta.detach()) if torch.is_tensor(beta) else float(beta)


def evaluate_sdf(field, points: torch.Tensor, dirs: torch.Tensor, chunk: int):
    """(sdf (N,), rgb (N, 3)) of ``field.sdf_rgb`` in chunks."""
    if len(points) == 0:
        return points.new_zeros(0), points.new_zeros(0, 3)
    return evaluate_field(field.sdf_rgb, points, dirs, chunk)


def render_rays_banded(field, beta, origins: torch.Tensor, dirs: torch.Tensor,
                       near: torch.Tensor, far: torch.Tensor, t_hit: torch.Tensor,
                       cos: torch.Tensor, settings, generator: torch.Generator | None = None,
                       shell=None, background=(0.0, 0.0, 0.0),
                       t_passing: torch.Tensor | None = None, index=None,
                       residual_misses: bool = True):
    """Volume-render rays as :func:`texvocab.render.marcher.render_rays` does, but:

    * rays with finite ``t_passing`` (R, 2) (rays that pass a surface nearer than their
      own, the places they come closest to it) first get two probes without gradient:
      where both read an SDF beyond ``miss_margin`` β the passed surface shows nothing (its
      density there is below e^-miss_margin / 2β, and so is the gradient the marcher would
      give it), and the ray shows the background when it has no ``t_hit``; otherwise the
      ray is marched;
    * rays with a finite ``t_hit`` (R,) (mesh hit at ``cos`` (R,) >= min_cos) and no close
      passed surface by the band — a probe and, with ``settings.band_newton``, two more
      evaluations (the Newton band, :func:`texvocab.render.residual.newton_band`), else
      ``band_samples`` (:func:`band_composite`);
    * with ``index`` (the posed mesh's :class:`~texvocab.geometry.surface.SurfaceIndex`)
      and ``settings.residual_rays``, the close passing rays (misses only with
      ``residual_misses``) and the band rays the band does not resolve as residual rays
      (:func:`texvocab.render.residual.render_residual`: the mesh's distance plus the
      field's residual, three evaluations), from their probes;
    * the rest, and the rays these do not resolve, by the shell marcher over [near, far].

    Differentiable w.r.t. the field's outputs and ``beta`` (float or the model's β
    tensor); the band's sample places carry no gradient (as importance samples do not).
    Returns a :class:`~texvocab.render.marcher.RayResult` (``banded``: band rays,
    ``residual``: residual rays)."""
    from texvocab.render.marcher import RayResult, render_rays  # the marcher builds on us
    from texvocab.render.residual import newton_band, render_residual  # so does residual

    s = settings
    R = len(origins)
    bg = torch.as_tensor(background, dtype=origins.dtype)
    close = torch.zeros(R, dtype=torch.bool)  # the ray passes a surface within the margin
    evals = 0
    # each ray's probes, for the residual rays: the two passing places, the mesh hit
    probe_t = origins.new_full((R, 3), torch.inf)
    probe_sdf = origins.new_full((R, 3), torch.inf)
    if t_passing is not None:
        p_idx = torch.nonzero(torch.isfinite(t_passing[:, 0])).squeeze(1)
        o, d = origins[p_idx], dirs[p_idx]
        with torch.no_grad():
            sdf_p, _ = evaluate_sdf(field, (o[:, None] + t_passing[p_idx, :, None] * d[:, None])
                                    .reshape(-1, 3), d.repeat_interleave(2, 0), s.chunk_points)
        evals += 2 * len(p_idx)
        close[p_idx] = sdf_p.view(-1, 2).min(1).values <= s.miss_margin * beta_value(beta)
        probe_t[p_idx, :2], probe_sdf[p_idx, :2] = t_passing[p_idx], sdf_p.view(-1, 2)
    b_idx = torch.nonzero(torch.isfinite(t_hit) & ~close).squeeze(1)
    o, d, t_b = origins[b_idx], dirs[b_idx], t_hit[b_idx]
    sdf0, rgb0 = evaluate_sdf(field, o + t_b[:, None] * d, d, s.chunk_points)
    if s.band_newton:  # the probe, the Newton point and one behind it
        acc, color, depth, ok = newton_band(field, o, d, t_b, cos[b_idx], sdf0, rgb0, beta, s)
        evals += len(b_idx) * 3
    else:
        acc, color, depth, ok = band_composite(field, s, beta, o, d, t_b, cos[b_idx], sdf0,
                                               rgb0)
        evals += len(b_idx) * (1 + s.band_samples)
    marched = torch.ones(R, dtype=torch.bool)
    marched[b_idx[ok]] = False
    if t_passing is not None:  # misses that pass a surface far away: the background
        marched[torch.isfinite(t_passing[:, 0]) & ~close & ~torch.isfinite(t_hit)] = False
    good = b_idx[ok]
    rgb = bg.repeat(R, 1).index_put((good,), color[ok] + (1 - acc[ok])[:, None] * bg)
    opacity = origins.new_zeros(R).index_put((good,), acc[ok])
    depth = origins.new_zeros(R).index_put((good,), depth[ok])
    resolved = 0
    if index is not None and s.residual_rays:
        probe_t[b_idx, 2], probe_sdf[b_idx, 2] = t_b, sdf0.detach()
        take = marched & torch.isfinite(probe_sdf).any(1)
        if not residual_misses:
            take &= torch.isfinite(t_hit)
        r_idx = torch.nonzero(take).squeeze(1)
        acc_r, color_r, depth_r, ok_r, n = render_residual(
            field, index, origins[r_idx], dirs[r_idx], near[r_idx], far[r_idx],
            probe_t[r_idx], probe_sdf[r_idx], beta, s)
        evals += n
        done = r_idx[ok_r]
        marched[done] = False
        resolved = len(done)
        rgb = rgb.index_put((done,), color_r[ok_r] + (1 - acc_r[ok_r])[:, None] * bg)
        opacity = opacity.index_put((done,), acc_r[ok_r])
        depth = depth.index_put((done,), depth_r[ok_r])
    m_idx = torch.nonzero(marched).squeeze(1)
    rest = render_rays(field, origins[m_idx], dirs[m_idx], near[m_idx], far[m_idx], s,
                       generator, shell, background) if len(m_idx) else None
    if rest is not None:
        rgb = rgb.index_put((m_idx,), rest.rgb)
        opacity = opacity.index_put((m_idx,), rest.opacity)
        depth = depth.index_put((m_idx,), rest.depth)
        evals += rest.field_evals
    return RayResult(rgb, opacity, depth, evals, banded=len(good), residual=resolved)
