"""Surface-guided marcher: the posed mesh's rasterisation tells each ray where its surface
is, the field's SDF refines it, and a few samples around it are composited with the
VolSDF opacity integrated in closed form (:mod:`texvocab.render.volume.volsdf`).

The avatar's SDF is the posed body's signed distance plus a residual, and its density is
zero beyond the shell (δ from the mesh) — so a ray's first surface lies within δ of the
mesh's first hit, known for every pixel from one rasterisation (:mod:`.plan`). One
function triages every ray, for images and for training (:mod:`.triage`):

* **band** (the ray hits the mesh at a cosine >= ``band.min_cos``, and any nearer surface
  it passes is more than ``band.miss_margin`` β away): one *probe* evaluation at the mesh
  hit t_m gives the SDF s_0; the surface is at t* ≈ t_m + s_0 / cos (one Newton step along
  the ray with the face's cosine). With ``band.newton`` (default) two more evaluations, at
  t* and ``band.spacing`` β / cos behind it, give the residual and colour there; the SDF
  between is the hit face's plane plus the residual interpolated. Otherwise
  ``band.samples`` samples spaced ``band.spacing`` β / cos around t* are evaluated in one
  call (:mod:`.band`). Either way the SDF is taken linear between samples and the VolSDF
  optical depth of each interval is exact for it. A ray whose samples do not bracket the
  surface (first SDF > 0 > last) or leave more than ``band.leftover`` transmittance is not
  resolved by the band.
* **passing rays** (no mesh hit, or a hit behind a surface that is more than δ nearer in
  the pixels within ``band.miss_margin`` β): two probes where the ray comes closest to the
  passed surface (at the nearest surface point, and a pixel footprint per pixel of
  distance behind it, where a silhouette's tangent point lies). Both beyond
  ``band.miss_margin`` β: the passed surface shows nothing (density < e^-miss_margin / 2β),
  and a miss sees the background.
* **residual rays** (``residual.enabled``, default: close passing rays, grazing hits,
  bands not resolved): the mesh's distance along the ray (exact, no network) plus the
  field's residual interpolated between three evaluations where the ray's weight lies
  (:mod:`.residual`).
* **fallback** (the rays the residual rays do not resolve, or all of the above without
  them): the shell marcher (:func:`texvocab.render.shell.march.render_rays`) with the same
  settings over the ray's in-shell path, in larger calls (the fallback group) — exact up
  to its sampling.

Field calls per frame: one for the probes, one for the bands, one for the residual rays
and a few for the fallback rays, against tens for front-to-back marching of every ray,
whose small calls pay the field's fixed per-call cost. Images are rendered in pixel
subsets (:mod:`.image`), which the progressive levels use (:mod:`.levels`).
"""

from texvocab.render.guided.image import GuidedImage, render_image_guided
from texvocab.render.guided.levels import guided_levels, level_owners
from texvocab.render.guided.plan import SurfacePlan, plan_surface
from texvocab.render.guided.triage import GuidedRays, render_rays_banded, triage_rays

__all__ = [
    "GuidedImage",
    "GuidedRays",
    "SurfacePlan",
    "guided_levels",
    "level_owners",
    "plan_surface",
    "render_image_guided",
    "render_rays_banded",
    "triage_rays",
]
