"""Surface-guided marcher: the posed mesh's rasterisation tells each ray where its surface
is, the field's SDF refines it, and a few samples around it are composited with the
VolSDF opacity integrated in closed form (:mod:`texvocab.render.band`, which training
shares through :func:`~texvocab.render.band.render_rays_banded`).

The avatar's SDF is the posed body's signed distance plus a residual, and its density is
zero beyond the shell (δ from the mesh) — so a ray's first surface lies within δ of the
mesh's first hit, known for every pixel from one rasterisation. Per pixel:

* **band** (the ray hits the mesh at a cosine >= ``min_cos``, and any nearer surface it
  passes is more than ``miss_margin`` β away): one *probe* evaluation at the mesh hit
  t_m gives the SDF s_0; the surface is at t* ≈ t_m + s_0 / cos (one Newton step along
  the ray with the face's cosine). With ``band_newton`` (default) two more evaluations,
  at t* and ``band_spacing`` β / cos behind it, give the residual and colour there; the
  SDF between is the hit face's plane plus the residual interpolated
  (:func:`texvocab.render.residual.newton_band`). Otherwise ``band_samples`` samples
  spaced ``band_spacing`` β / cos around t* are evaluated in one call. Either way the
  SDF is taken linear between samples and the VolSDF optical depth of each interval is
  exact for it (:func:`interval_optical_depth`). A ray whose samples do not bracket the
  surface (first SDF > 0 > last) or leave more than ``band_leftover`` transmittance is
  not resolved by the band.
* **passing rays** (no mesh hit, or a hit behind a surface that is more than δ nearer in
  the pixels within ``miss_margin`` β): two probes where the ray comes closest to the
  passed surface (at the nearest surface point, and a pixel footprint per pixel of
  distance behind it, where a silhouette's tangent point lies). Both beyond
  ``miss_margin`` β: the passed surface shows nothing (density < e^-miss_margin / 2β),
  and a miss sees the background.
* **residual rays** (``residual_rays``, default: close passing rays, grazing hits,
  bands not resolved): the mesh's distance along the ray (exact, no network) plus the
  field's residual interpolated between three evaluations where the ray's weight lies
  (:mod:`texvocab.render.residual`).
* **fallback** (the rays the residual rays do not resolve, or all of the above without
  them): the shell marcher (:func:`texvocab.render.marcher.render_rays`) with the same
  settings over the ray's in-shell path, in larger calls (``fallback_segment``) — exact
  up to its sampling.

Field calls per frame: one for the probes, one for the bands, one for the residual rays
and a few for the fallback rays, against tens for front-to-back marching of every ray,
whose small calls pay the field's fixed per-call cost.
"""
from __future__ import annotations

import time
from dataclasses import replace

import torch

from texvocab.render.band import (
    band_composite,
    composite_linear_sdf,
    evaluate_sdf,
    interval_optical_depth,
    laplace_antiderivative,
    plan_surface,
)
from texvocab.render.marcher import (
    MarchSettings,
    RenderCancelled,
    RenderResult,
    RenderStats,
    render_rays,
)
from texvocab.render.residual import newton_band, render_residual
from texvocab.render.shell import ShellGeometry


def render_image_guided(field, camera, vertices, faces, settings: MarchSettings | None = None,
                        background=(0.0, 0.0, 0.0), cancelled=None,
                        shell: ShellGeometry | None = None, index=None) -> RenderResult:
    """Render one image of ``field`` around the posed mesh (vertices (V, 3), faces (F, 3)).

    ``field`` is the marcher's ``(points, dirs) -> (density, rgb)`` callable that also
    has ``sdf_rgb(points, dirs) -> (sdf (N,), rgb (N, 3))`` and ``beta`` (float), with
    density = VolSDF(sdf, beta) (:class:`texvocab.method.field.PoseField`, the analytic
    fields of texvocab.render.analytic). Not differentiable (render time only).
    ``stats.paths`` counts the rays of each kind (band, residual, fallback, background)
    and ``stats.kind`` (H, W) marks them (1 background, 2 band, 3 fallback, 4 residual).
    The fallback rays are marched by the shell marcher with the same settings; ``shell``
    (the posed mesh's :class:`ShellGeometry`, whose bounds the residual rays use too) is
    built when first needed if not given, and ``index`` (its
    :class:`~texvocab.geometry.surface.SurfaceIndex`) likewise for the residual rays.
    """
    image = GuidedImage(field, camera, vertices, faces, settings, background, shell, index)
    image.render(None, cancelled)
    return image.result()


class GuidedImage:
    """One image of the surface-guided marcher, rendered in any pixel subsets: the plan
    (rasterisation and each ray's class) is made once for the whole image, then
    :meth:`render` evaluates the rays of a subset; every ray's result depends only on the
    plan and the field, so rendering the image in parts (coarse pixel grids first, as the
    viewer's progressive levels) gives the same image with no ray rendered twice.

    ``shell``: the posed mesh's :class:`ShellGeometry`, or a function that builds it
    (called the first time a ray falls back), or None (built then from the mesh).
    ``index``: the posed mesh's SurfaceIndex for the passing rays (None: built when
    first needed)."""

    def __init__(self, field, camera, vertices, faces, settings: MarchSettings | None = None,
                 background=(0.0, 0.0, 0.0), shell=None, index=None):
        s = self.settings = settings or MarchSettings()
        self.start = time.perf_counter()
        self.field, self.camera, self.shell, self.index = field, camera, shell, index
        self._bounds = None
        self.beta, delta = float(field.beta), float(s.shell_width)
        H, W = self.H, self.W = camera.height, camera.width
        self.bg = torch.as_tensor(background, dtype=torch.float32)
        self.verts = torch.as_tensor(vertices).detach().float()
        self.faces = torch.as_tensor(faces).long()
        self.origins, dirs = camera.pixel_rays()
        self.dirs = dirs
        # a surface farther than `reach` from a ray contributes < e^-miss_margin / 2β density
        reach = min(delta, s.miss_margin * self.beta)
        plan = plan_surface(self.verts, self.faces, camera, dirs, delta, reach, s.min_cos)
        hit = self.hit = plan.hit
        self.t_hit, self.cos, self.passby = plan.t_hit, plan.cos, plan.passby
        self.rgb = self.bg.repeat(H * W, 1)
        self.alpha, self.depth = torch.zeros(H * W), torch.zeros(H * W)
        self.paths = {"band": 0, "residual": 0, "fallback": 0, "background": 0}
        # 0 untouched, 1 background, 2 band, 3 fallback (marched), 4 residual
        self.kind = torch.zeros(H * W, dtype=torch.uint8)
        self.evals = 0
        self.deferred = torch.zeros(H * W, dtype=torch.bool)  # fallback rays left for later
        if not hit.any():
            return
        self.t_pass, self.t_behind = plan.t_pass, plan.t_behind

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
        # hits get a probe; grazing ones only for the residual rays, which start from it
        h_idx = torch.nonzero(hit & ((cos >= s.min_cos) | s.residual_rays) & sub).squeeze(1)
        idx = torch.cat([p_idx, p_idx, h_idx])
        t_probe = torch.cat([self.t_pass[p_idx], self.t_behind[p_idx], self.t_hit[h_idx]])
        check()
        sdf0, rgb0 = evaluate_sdf(field, o + t_probe[:, None] * dirs[idx], dirs[idx],
                                   s.chunk_points)
        self.evals += len(idx)
        n_p = len(p_idx)
        close = torch.zeros(self.H * self.W, dtype=torch.bool)
        close[p_idx] = torch.minimum(sdf0[:n_p], sdf0[n_p:2 * n_p]) <= s.miss_margin * beta
        empty = passby & ~close & ~hit & sub
        self.paths["background"] += int(empty.sum())
        self.kind[empty] = 1
        # hits at a cosine >= min_cos whose passed surface (if any) shows nothing
        alone = ~close[h_idx] & (cos[h_idx] >= s.min_cos)
        band_idx = h_idx[alone]
        if s.band_newton:
            acc, color, depth, ok = newton_band(field, o, dirs[band_idx], self.t_hit[band_idx],
                                                cos[band_idx], sdf0[2 * n_p:][alone],
                                                rgb0[2 * n_p:][alone], beta, s)
            self.evals += 2 * len(band_idx)
        else:
            acc, color, depth, ok = band_composite(field, s, beta, o, dirs[band_idx],
                                                   self.t_hit[band_idx], cos[band_idx],
                                                   sdf0[2 * n_p:][alone], rgb0[2 * n_p:][alone])
            self.evals += len(band_idx) * s.band_samples
        good = band_idx[ok]
        self.rgb[good] = color[ok] + (1 - acc[ok])[:, None] * self.bg  # acc = 1: ends inside
        self.alpha[good], self.depth[good] = acc[ok], depth[ok]
        self.paths["band"] += int(ok.sum())
        self.kind[band_idx[ok]] = 2
        fb = close | (hit & (cos < s.min_cos) & sub)
        fb[band_idx[~ok]] = True
        if s.residual_rays and not defer_fallback and fb.any():
            check()
            probe_t = torch.full((self.H * self.W, 3), torch.inf)
            probe_sdf = probe_t.clone()
            probe_t[p_idx, 0], probe_t[p_idx, 1] = self.t_pass[p_idx], self.t_behind[p_idx]
            probe_t[h_idx, 2] = self.t_hit[h_idx]
            probe_sdf[p_idx, 0], probe_sdf[p_idx, 1] = sdf0[:n_p], sdf0[n_p:2 * n_p]
            probe_sdf[h_idx, 2] = sdf0[2 * n_p:]
            r_idx = torch.nonzero(fb).squeeze(1)
            fb[self._residual(r_idx, probe_t[r_idx], probe_sdf[r_idx])] = False
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

    def _shell_bounds(self, grid: bool = False):
        """The posed mesh's shell and its image bounds, built on first use: its bounding
        balls only, unless ``grid`` (the shell marcher's occupancy grid) is asked for."""
        s = self.settings
        if callable(self.shell):
            self.shell = self.shell()
        if self.shell is None or (grid and not self.shell.has_grid):
            self.shell = ShellGeometry.build(self.verts, self.faces, float(s.shell_width),
                                             s.shell_voxel, s.shell_exact, self.index, grid)
        if self._bounds is None:  # the balls, hence the bounds, do not depend on the grid
            self._bounds = self.shell.image_bounds(self.camera)
        return self.shell, self._bounds

    def _index(self):
        """The posed mesh's SurfaceIndex (built on first use when not given)."""
        if self.index is None:
            from texvocab.geometry.surface import SurfaceIndex

            self.index = SurfaceIndex(self.verts.double().numpy(), self.faces.numpy())
        return self.index

    def _residual(self, idx: torch.Tensor, t_probe: torch.Tensor,
                  sdf_probe: torch.Tensor) -> torch.Tensor:
        """Render rays idx (R,) (probes at t_probe (R, P) read sdf_probe (R, P), inf
        where none) from the mesh distance and the field's residual
        (:mod:`texvocab.render.residual`); returns the rays resolved."""
        if len(idx) == 0:
            return idx
        _, bounds = self._shell_bounds()
        near, far = bounds.near.view(-1)[idx], bounds.far.view(-1)[idx]
        acc, color, depth, ok, evals = render_residual(
            self.field, self._index(), self.origins[0], self.dirs[idx], near, far, t_probe,
            sdf_probe, self.beta, self.settings)
        self.evals += evals
        good = idx[ok]
        self.rgb[good] = color[ok] + (1 - acc[ok])[:, None] * self.bg
        self.alpha[good], self.depth[good] = acc[ok], depth[ok]
        self.paths["residual"] += len(good)
        self.kind[good] = 4
        return good

    def _fallback(self, f_idx: torch.Tensor, check) -> None:
        s = self.settings
        check()
        shell, bounds = self._shell_bounds(grid=True)
        near, far = bounds.near.view(-1)[f_idx], bounds.far.view(-1)[f_idx]
        fs = replace(s, segment=s.fallback_segment, scout_threshold=s.fallback_scout)
        for c in range(0, len(f_idx), s.chunk_rays):
            check()
            sl = f_idx[c:c + s.chunk_rays]
            out = render_rays(self.field, self.origins[sl], self.dirs[sl],
                              near[c:c + s.chunk_rays], far[c:c + s.chunk_rays], fs, None,
                              shell, self.bg)
            self.rgb[sl], self.alpha[sl], self.depth[sl] = out.rgb, out.opacity, out.depth
            self.evals += out.field_evals

    def result(self) -> RenderResult:
        H, W = self.H, self.W
        stats = RenderStats(self.evals, self.paths["band"] + self.paths["residual"]
                            + self.paths["fallback"], H * W,
                            time.perf_counter() - self.start)
        stats.paths = dict(self.paths)  # type: ignore[attr-defined]
        stats.kind = self.kind.view(H, W)  # type: ignore[attr-defined]
        return RenderResult(self.rgb.view(H, W, 3), self.alpha.view(H, W),
                            self.depth.view(H, W), stats)


__all__ = ["GuidedImage", "composite_linear_sdf", "interval_optical_depth",
           "laplace_antiderivative", "render_image_guided"]
