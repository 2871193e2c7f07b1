"""Surface-guided marcher: the posed mesh's rasterisation tells each ray where its surface
is, the field's SDF refines it, and a few samples around it are composited with the
VolSDF opacity integrated in closed form (render time only; training keeps the shell
marcher, :func:`texvocab.render.marcher.render_rays`).

The avatar's SDF is the posed body's signed distance plus a residual, and its density is
zero beyond the shell (δ from the mesh) — so a ray's first surface lies within δ of the
mesh's first hit, known for every pixel from one rasterisation. Per pixel:

* **band** (the ray hits the mesh at a cosine >= ``min_cos``, and any nearer surface it
  passes is more than ``miss_margin`` β away): one *probe* evaluation at the mesh hit
  t_m gives the SDF s_0; the surface is at t* ≈ t_m + s_0 / cos (one Newton step along
  the ray with the face's cosine); ``band_samples`` samples spaced ``band_spacing``
  β / cos around t* are evaluated in one call. Between samples the SDF is taken linear
  and the VolSDF optical depth of each interval is exact for it
  (:func:`interval_optical_depth`): with β ≈ 2 mm a handful of samples integrate the
  surface's opacity profile that a Riemann sum needs dozens for. The part of the ray in
  front of the first sample is integrated along the same line; the transmittance left
  after the last sample goes to its colour (as early termination does). A ray whose
  samples do not bracket the surface (first SDF > 0 > last) or leave more than
  ``band_leftover`` transmittance falls back.
* **passing rays** (no mesh hit, or a hit behind a surface that is more than δ nearer in
  the pixels within ``miss_margin`` β): two probes where the ray comes closest to the
  passed surface (at the nearest surface point, and a pixel footprint per pixel of
  distance behind it, where a silhouette's tangent point lies). Both beyond
  ``miss_margin`` β: the passed surface shows nothing (density < e^-miss_margin / 2β),
  and a miss sees the background. Otherwise the ray falls back.
* **fallback** (close passing rays, grazing hits, failed bands): the shell marcher
  (:func:`texvocab.render.marcher.render_rays`) with the same settings over the ray's
  in-shell path, in larger calls (``fallback_segment``) — exact up to its sampling.

Field calls per frame: one for the probes, one for the bands, and a few for the fallback
rays, against tens for front-to-back marching of every ray, whose small calls pay the
field's fixed per-call cost.
"""
from __future__ import annotations

import math
import time
from dataclasses import replace

import torch
import torch.nn.functional as F
from scipy import ndimage

from texvocab.geometry.raster import rasterize_mesh
from texvocab.render.coarse import evaluate_field
from texvocab.render.marcher import (
    MarchSettings,
    RenderCancelled,
    RenderResult,
    RenderStats,
    render_rays,
)
from texvocab.render.shell import ShellGeometry

_FAR = 1e6  # stands for "no surface" in the min/max filters (metres)


def laplace_antiderivative(s: torch.Tensor, beta: float) -> torch.Tensor:
    """F(s) = ∫ Ψ_β(-s) ds with F(+∞) = 0: -β/2 e^(-s/β) for s >= 0, s - β/2 e^(s/β) below
    (Ψ_β the Laplace CDF of VolSDF's density σ = Ψ_β(-s) / β)."""
    e = torch.exp(-s.abs() / beta)
    return torch.where(s >= 0, -0.5 * beta * e, s - 0.5 * beta * e)


def interval_optical_depth(s_a: torch.Tensor, s_b: torch.Tensor, length: torch.Tensor,
                           beta: float) -> torch.Tensor:
    """∫ σ dt over an interval of ``length`` where the SDF runs linearly from s_a to s_b:
    length (F(s_a) - F(s_b)) / (β (s_a - s_b)); the density at the mean SDF times the
    length where |s_a - s_b| < 1e-4 β (where the quotient loses precision)."""
    ds = s_a - s_b
    flat = ds.abs() < 1e-4 * beta
    exact = (laplace_antiderivative(s_a, beta) - laplace_antiderivative(s_b, beta)) / \
        torch.where(flat, torch.ones_like(ds), ds)
    mid = 0.5 * (s_a + s_b)
    density = torch.where(mid >= 0, 0.5 * torch.exp(-mid / beta),
                          1 - 0.5 * torch.exp(mid / beta))
    return length * torch.where(flat, density, exact) / beta


def composite_linear_sdf(t: torch.Tensor, sdf: torch.Tensor, rgb: torch.Tensor, beta: float
                         ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Volume-render rays from sorted samples (R, S) of a piecewise-linear SDF.

    Intervals between samples get their closed-form optical depth and the mean of their
    end colours; the ray in front of the first sample continues the first interval's
    line (σ integrated from s = +∞, the first sample's colour); the transmittance left
    after the last sample goes to the last colour where that sample is inside (SDF < 0:
    the ray ends in the body) and to the background otherwise (it passed by).

    Returns opacity (R,), colour (R, 3) (not over a background), expected depth (R,)
    and the transmittance (R,) left after the last sample.
    """
    dt = (t[:, 1:] - t[:, :-1]).clamp(min=0)
    tau = interval_optical_depth(sdf[:, :-1], sdf[:, 1:], dt, beta)
    slope = ((sdf[:, 0] - sdf[:, 1]) / dt[:, 0].clamp(min=1e-9)).clamp(min=1e-3)
    tau_pre = (-laplace_antiderivative(sdf[:, 0], beta) / (beta * slope)).clamp(min=0)
    taus = torch.cat([tau_pre[:, None], tau], 1)  # (R, S)
    before = torch.cumsum(taus, 1) - taus
    weights = torch.exp(-before) * -torch.expm1(-taus)
    colours = torch.cat([rgb[:, :1], 0.5 * (rgb[:, 1:] + rgb[:, :-1])], 1)
    places = torch.cat([t[:, :1], 0.5 * (t[:, 1:] + t[:, :-1])], 1)
    rest = torch.exp(-taus.sum(1))
    ends = (sdf[:, -1] < 0).to(rest.dtype) * rest  # absorbed by the last sample
    color = (weights[..., None] * colours).sum(1) + ends[:, None] * rgb[:, -1]
    acc = weights.sum(1) + ends
    depth = ((weights * places).sum(1) + ends * t[:, -1]) / acc.clamp(min=1e-6)
    return acc, color, depth, rest


def _frontmost_neighbour(t_map: torch.Tensor, radius: int) -> tuple[torch.Tensor, torch.Tensor]:
    """For each pixel of t_map (H, W) (ray distance of the mesh hit, inf where missed):
    the smallest hit distance within its (2 radius + 1)² window (_FAR where none) and the
    flat index of the pixel that has it."""
    hit = torch.isfinite(t_map)
    k = 2 * radius + 1
    neg, idx = F.max_pool2d(-torch.where(hit, t_map, _FAR)[None, None], k, 1, radius,
                            return_indices=True)
    return -neg[0, 0].reshape(-1), idx[0, 0].reshape(-1)


def render_image_guided(field, camera, vertices, faces, settings: MarchSettings | None = None,
                        background=(0.0, 0.0, 0.0), cancelled=None,
                        shell: ShellGeometry | None = None) -> RenderResult:
    """Render one image of ``field`` around the posed mesh (vertices (V, 3), faces (F, 3)).

    ``field`` is the marcher's ``(points, dirs) -> (density, rgb)`` callable that also
    has ``sdf_rgb(points, dirs) -> (sdf (N,), rgb (N, 3))`` and ``beta`` (float), with
    density = VolSDF(sdf, beta) (:class:`texvocab.method.field.PoseField`, the analytic
    fields of texvocab.render.analytic). Not differentiable (render time only).
    ``stats.paths`` counts the rays of each kind (band, fallback, background) and
    ``stats.kind`` (H, W) marks them (1 background, 2 band, 3 fallback). The fallback
    rays are marched by the shell marcher with the same settings; ``shell`` (the posed
    mesh's :class:`ShellGeometry`) is built for them when not given.
    """
    image = GuidedImage(field, camera, vertices, faces, settings, background, shell)
    image.render(None, cancelled)
    return image.result()


class GuidedImage:
    """One image of the surface-guided marcher, rendered in any pixel subsets: the plan
    (rasterisation and each ray's class) is made once for the whole image, then
    :meth:`render` evaluates the rays of a subset; every ray's result depends only on the
    plan and the field, so rendering the image in parts (coarse pixel grids first, as the
    viewer's progressive levels) gives the same image with no ray rendered twice.

    ``shell``: the posed mesh's :class:`ShellGeometry`, or a function that builds it
    (called the first time a ray falls back), or None (built then from the mesh)."""

    def __init__(self, field, camera, vertices, faces, settings: MarchSettings | None = None,
                 background=(0.0, 0.0, 0.0), shell=None):
        s = self.settings = settings or MarchSettings()
        self.start = time.perf_counter()
        self.field, self.camera, self.shell = field, camera, shell
        self.beta, delta = float(field.beta), float(s.shell_width)
        H, W = self.H, self.W = camera.height, camera.width
        self.bg = torch.as_tensor(background, dtype=torch.float32)
        self.verts = torch.as_tensor(vertices).detach().float()
        self.faces = torch.as_tensor(faces).long()
        raster = rasterize_mesh(self.verts, self.faces, camera)
        self.origins, dirs = camera.pixel_rays()
        self.dirs = dirs
        along_z = dirs.double() @ torch.as_tensor(camera.R[2], dtype=torch.float64)
        t_map = (raster.depth.view(-1).double() / along_z).float().view(H, W)
        hit = self.hit = torch.isfinite(t_map).view(-1)
        self.rgb = self.bg.repeat(H * W, 1)
        self.alpha, self.depth = torch.zeros(H * W), torch.zeros(H * W)
        self.paths = {"band": 0, "fallback": 0, "background": 0}
        self.kind = torch.zeros(H * W, dtype=torch.uint8)  # 0 untouched, 1 bg, 2 band, 3 fallback
        self.evals = 0
        self.passby = torch.zeros(H * W, dtype=torch.bool)
        self.deferred = torch.zeros(H * W, dtype=torch.bool)  # fallback rays left for later
        if not hit.any():
            return
        # a surface farther than `reach` from a ray contributes < e^-miss_margin / 2β density
        reach = min(delta, s.miss_margin * self.beta)
        z_min = float(raster.depth.view(-1)[hit].min())
        radius = min(int(math.ceil(reach * float(camera.K[0, 0]) / max(z_min, 1e-6))), 64)
        t_hit = self.t_hit = t_map.view(-1)
        front, front_pix = _frontmost_neighbour(t_map, max(radius, 1))
        tri = self.verts[self.faces]
        normal = F.normalize(torch.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], dim=1),
                             dim=1)
        cos = self.cos = torch.zeros(H * W)
        cos[hit] = (normal[raster.face.view(-1)[hit]] * dirs[hit]).sum(1).abs()
        # rays that pass a surface nearer than their own (or miss the mesh): a neighbour
        # hit nearer by more than δ plus what the hit face's own slope explains
        c = cos.clamp(min=s.min_cos)
        slope = radius * t_hit / float(camera.K[0, 0]) * (1 - c * c).sqrt() / c
        own = torch.where(hit & (cos >= s.min_cos), t_hit - slope, t_hit)
        self.passby = (front < _FAR / 2) & (front < torch.where(hit, own, torch.inf) - delta)
        # A passing ray is probed where it comes closest to the surface it passes: a miss
        # near the nearest hit pixel's surface point, a hit behind an occlusion edge near
        # the nearest surface point of its window. The silhouette's tangent point lies up
        # to a pixel footprint per pixel of distance behind that point, where a second
        # probe looks. Both probes beyond miss_margin β: the passed surface shows nothing.
        gap, (iy, ix) = ndimage.distance_transform_edt(~hit.view(H, W).numpy(),
                                                       return_indices=True)
        gap = torch.from_numpy(gap).float().view(-1)
        nearest = torch.where(hit, front_pix, torch.from_numpy((iy * W + ix).reshape(-1)))
        gap = torch.where(hit, float(radius), gap)
        p_idx = torch.nonzero(self.passby).squeeze(1)
        q = nearest[p_idx]
        self.t_pass = torch.full((H * W,), torch.inf)
        self.t_pass[p_idx] = ((t_hit[q, None] * dirs[q]) * dirs[p_idx]).sum(1)
        self.t_behind = torch.full((H * W,), torch.inf)
        self.t_behind[p_idx] = self.t_pass[p_idx] * (1 + gap[p_idx] / float(camera.K[0, 0]))

    def render(self, subset: torch.Tensor | None = None, cancelled=None,
               defer_fallback: bool = False) -> None:
        """Render the rays of ``subset`` ((H·W,) bool; None: all) into the image, and any
        rays an earlier call deferred. ``defer_fallback``: rays that fall back to the shell
        marcher are not marched now but shown with their probe's colour (hits) or the
        background (passing rays) — a preview — and rendered by the next call."""
        if not self.hit.any():
            return
        s, beta, field = self.settings, self.beta, self.field
        sub = torch.ones_like(self.hit) if subset is None else subset.view(-1)
        sub = sub | self.deferred
        self.deferred = torch.zeros_like(self.deferred)

        def check():
            if cancelled is not None and cancelled():
                raise RenderCancelled

        o, dirs, hit, cos, passby = self.origins[0], self.dirs, self.hit, self.cos, self.passby
        p_idx = torch.nonzero(passby & sub).squeeze(1)
        h_idx = torch.nonzero(hit & (cos >= s.min_cos) & sub).squeeze(1)
        idx = torch.cat([p_idx, p_idx, h_idx])
        t_probe = torch.cat([self.t_pass[p_idx], self.t_behind[p_idx], self.t_hit[h_idx]])
        check()
        sdf0, rgb0 = _evaluate_sdf(field, o + t_probe[:, None] * dirs[idx], dirs[idx],
                                   s.chunk_points)
        self.evals += len(idx)
        n_p = len(p_idx)
        close = torch.zeros(self.H * self.W, dtype=torch.bool)
        close[p_idx] = torch.minimum(sdf0[:n_p], sdf0[n_p:2 * n_p]) <= s.miss_margin * beta
        empty = passby & ~close & ~hit & sub
        self.paths["background"] += int(empty.sum())
        self.kind[empty] = 1
        alone = ~close[h_idx]  # hits whose passed surface (if any) shows nothing
        band_idx = h_idx[alone]
        ok = _band(field, s, beta, o, dirs, band_idx, self.t_hit, cos, sdf0[2 * n_p:][alone],
                   rgb0[2 * n_p:][alone], self.rgb, self.alpha, self.depth, self.bg)
        self.evals += len(band_idx) * s.band_samples
        self.paths["band"] += int(ok.sum())
        self.kind[band_idx[ok]] = 2
        fb = close | (hit & (cos < s.min_cos) & sub)
        fb[band_idx[~ok]] = True
        if defer_fallback:
            self.deferred = fb
            preview = self.bg.repeat(self.H * self.W, 1)
            preview[idx[2 * n_p:]] = rgb0[2 * n_p:]  # the colour at the mesh hit
            self.rgb[fb] = preview[fb]
            return
        f_idx = torch.nonzero(fb).squeeze(1)
        self.paths["fallback"] += len(f_idx)
        self.kind[f_idx] = 3
        if len(f_idx):
            self._fallback(f_idx, check)

    def _fallback(self, f_idx: torch.Tensor, check) -> None:
        s = self.settings
        check()
        if self.shell is None:
            self.shell = ShellGeometry.build(self.verts, self.faces, float(s.shell_width),
                                             s.shell_voxel, s.shell_exact)
        elif callable(self.shell):
            self.shell = self.shell()
        bounds = self.shell.image_bounds(self.camera)
        near, far = bounds.near.view(-1)[f_idx], bounds.far.view(-1)[f_idx]
        fs = replace(s, segment=s.fallback_segment, scout_threshold=s.fallback_scout)
        for c in range(0, len(f_idx), s.chunk_rays):
            check()
            sl = f_idx[c:c + s.chunk_rays]
            out = render_rays(self.field, self.origins[sl], self.dirs[sl],
                              near[c:c + s.chunk_rays], far[c:c + s.chunk_rays], fs, None,
                              self.shell, self.bg)
            self.rgb[sl], self.alpha[sl], self.depth[sl] = out.rgb, out.opacity, out.depth
            self.evals += out.field_evals

    def result(self) -> RenderResult:
        H, W = self.H, self.W
        stats = RenderStats(self.evals, self.paths["band"] + self.paths["fallback"], H * W,
                            time.perf_counter() - self.start)
        stats.paths = dict(self.paths)  # type: ignore[attr-defined]
        stats.kind = self.kind.view(H, W)  # type: ignore[attr-defined]
        return RenderResult(self.rgb.view(H, W, 3), self.alpha.view(H, W),
                            self.depth.view(H, W), stats)


def _band(field, s: MarchSettings, beta: float, o, dirs, idx, t_hit, cos, sdf0, rgb0,
          rgb_out, alpha_out, depth_out, bg) -> torch.Tensor:
    """The band path for rays idx (R,) with probe SDF sdf0 (R,) and colour rgb0 (R, 3) at
    their mesh hit: writes the rays it resolves into the outputs; returns which (R,)."""
    if len(idx) == 0:
        return torch.zeros(0, dtype=torch.bool)
    delta = float(s.shell_width)
    c = cos[idx]
    step = sdf0 / c  # Newton step along the ray with the face's cosine
    t_star = t_hit[idx] + step.clamp(-delta, delta)
    k = torch.arange(s.band_samples, dtype=torch.float32) - (s.band_samples - 1) / 2
    t_band = t_star[:, None] + k * (s.band_spacing * beta) / c[:, None]  # (R, B)
    d = dirs[idx]
    sdf_b, rgb_b = _evaluate_sdf(field, (o + t_band[..., None] * d[:, None]).reshape(-1, 3),
                                 d.repeat_interleave(s.band_samples, 0), s.chunk_points)
    t_all, order = torch.cat([t_hit[idx, None], t_band], 1).sort(1)
    sdf_all = torch.cat([sdf0[:, None], sdf_b.view(len(idx), -1)], 1).gather(1, order)
    rgb_all = torch.cat([rgb0[:, None], rgb_b.view(len(idx), -1, 3)], 1)
    rgb_all = rgb_all.gather(1, order[..., None].expand(-1, -1, 3))
    acc, color, depth, rest = composite_linear_sdf(t_all, sdf_all, rgb_all, beta)
    ok = (step.abs() <= delta) & (sdf_all[:, 0] > 0) & (sdf_all[:, -1] < 0) & \
        (rest <= s.band_leftover)
    good = idx[ok]
    rgb_out[good] = color[ok] + (1 - acc[ok])[:, None] * bg  # acc = 1: ends inside
    alpha_out[good], depth_out[good] = acc[ok], depth[ok]
    return ok


def _evaluate_sdf(field, points: torch.Tensor, dirs: torch.Tensor, chunk: int):
    """(sdf (N,), rgb (N, 3)) of ``field.sdf_rgb`` in chunks."""
    if len(points) == 0:
        return points.new_zeros(0), points.new_zeros(0, 3)
    return evaluate_field(field.sdf_rgb, points, dirs, chunk)


__all__ = ["GuidedImage", "composite_linear_sdf", "interval_optical_depth",
           "laplace_antiderivative", "render_image_guided"]
