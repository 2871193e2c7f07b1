"""Training rays: the per-frame and per-view caches a training step draws its rays from
(pose context, shell, image, mask, ray bounds and the surface plan of each view) and the
draws themselves — random rays, ``train.fg_fraction`` of them inside the mask, and the
perceptual term's patch. Each cache is built once, on first use, and its build time is
counted (``cache_seconds``; bench/train_speed.py reports steps with and without it).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import NamedTuple

import torch

from texvocab.render import ShellGeometry, plan_surface


class ViewData(NamedTuple):
    """One training view of one frame. Per pixel (H·W, row-major): img (·, 3) uint8, mask,
    hit (the ray meets the shell), slot (int32: the pixel's row in the per-hit arrays, −1
    where the ray misses the shell). Per hit pixel (n_hit, in pixel order): near, far (ray
    bounds), t_band (mesh hit of the band rays, inf elsewhere), cos (float16, the hit
    face's cosine), t_passing (·, 2) (where band rays behind an occlusion edge and rays
    outside the mask that miss the mesh pass closest to the surface they pass, inf
    elsewhere). A ray that misses the shell has an empty interval, no band and no passing
    places (:meth:`rays`): storing those per hit pixel only keeps a 512² view at about a
    sixth of its per-pixel size (ZJU-MoCap 387: 9.0 MiB a view before)."""

    img: torch.Tensor
    mask: torch.Tensor
    hit: torch.Tensor
    slot: torch.Tensor
    near: torch.Tensor
    far: torch.Tensor
    t_band: torch.Tensor
    cos: torch.Tensor
    t_passing: torch.Tensor

    @classmethod
    def compact(cls, img, mask, hit, near, far, t_band, cos, t_passing) -> ViewData:
        """From per-pixel arrays (as above, img float in [0, 1])."""
        idx = torch.nonzero(hit).squeeze(1)
        slot = torch.full(hit.shape, -1, dtype=torch.int32)
        slot[idx] = torch.arange(len(idx), dtype=torch.int32)
        img8 = (img.clamp(0, 1) * 255 + 0.5).to(torch.uint8)
        return cls(img8, mask, hit, slot, near[idx], far[idx], t_band[idx], cos[idx], t_passing[idx])

    def rays(self, pix: torch.Tensor):
        """(near, far, t_band, cos (float32), t_passing) of pixels ``pix`` (n,), the
        shell's misses with an empty interval [0, 0], no band and no passing places."""
        s = self.slot[pix].long()
        inside = s >= 0
        k = s.clamp(min=0)
        if len(self.near) == 0:  # no pixel meets the shell
            zero = torch.zeros(len(pix))
            inf = torch.full((len(pix),), torch.inf)
            return zero, zero, inf, zero, inf[:, None].expand(-1, 2).clone()
        near = torch.where(inside, self.near[k], 0.0)
        far = torch.where(inside, self.far[k], 0.0)
        t_band = torch.where(inside, self.t_band[k], torch.inf)
        cos = torch.where(inside, self.cos[k].float(), 0.0)
        t_passing = torch.where(inside[:, None], self.t_passing[k], torch.inf)
        return near, far, t_band, cos, t_passing

    def colours(self, pix: torch.Tensor) -> torch.Tensor:
        """(n, 3) float colours of pixels ``pix`` in [0, 1]."""
        return self.img[pix].float() / 255.0


@dataclass
class FrameData:
    """Per-frame cache: pose context (geometry), shell, and per-view images/masks/bounds."""

    ctx: object
    shell: ShellGeometry
    views: dict = field(default_factory=dict)


class TrainingRays:
    """Caches and ray draws of one training run: ``capture``, its ``settings``, the
    ``model`` (its pose contexts) and the training's ``march`` settings (the band's
    ``min_cos``, the shell grid's voxel and exactness)."""

    def __init__(self, capture, settings, model, march):
        self.capture, self.s, self.model, self.march = capture, settings, model, march
        self.frames: dict[int, FrameData] = {}
        self.cache_seconds = 0.0  # spent building the frame and view caches (one-off each)
        # view -> (origins, directions) (H·W, 3) of every pixel: the same every frame
        self.pixel_rays: dict[int, tuple[torch.Tensor, torch.Tensor]] = {}

    def frame(self, t: int) -> FrameData:
        """Frame t's cache (pose context and shell), built on first use."""
        if t not in self.frames:
            t0 = time.perf_counter()
            pf = self.model.pose_feature
            ctx = pf.context(self.capture.poses[t], self.capture.trans[t])
            m = self.march
            shell = ShellGeometry.build(
                ctx.vertices.detach(),
                self.capture.body.faces,
                self.s.field.shell_width,
                m.shell_voxel,
                m.shell_exact,
                index=ctx.index,
            )
            self.frames[t] = FrameData(ctx, shell)
            self.cache_seconds += time.perf_counter() - t0
        return self.frames[t]

    def view(self, fd: FrameData, t: int, v: int) -> ViewData:
        """Image, mask, per-pixel ray bounds and surface band of a view (cached). Rays that
        hit the body end δ behind its first surface: the interior is opaque, so nothing
        behind it can contribute, and training then evaluates no samples there. With
        ``train.guide=raster`` the band rays inside the mask keep their mesh hit and the
        rays outside it that miss the mesh their two probe places
        (:func:`~texvocab.render.guided.plan.plan_surface`), as do the band rays behind an
        occlusion edge; the band cannot lower a ray's opacity (it ends inside), so rays
        outside the mask never take it."""
        if v not in fd.views:
            t0 = time.perf_counter()
            cam = self.capture.cameras[v]
            img = torch.from_numpy(self.capture.image(v, t)).view(-1, 3)
            mask = torch.from_numpy(self.capture.mask(v, t)).view(-1)
            b = fd.shell.image_bounds(cam)
            far = b.far.view(-1).clone()
            _, dirs = self.rays_of(v)
            delta = self.s.field.shell_width
            plan = plan_surface(
                fd.ctx.vertices.detach(), self.capture.body.faces, cam, dirs, delta, delta, self.march.min_cos
            )
            first = plan.hit
            far[first] = torch.minimum(far[first], plan.t_hit[first] + delta)
            raster = self.s.train.guide == "raster"
            # inside the mask every hit at a cosine >= min_cos is a band ray; one behind an
            # occlusion edge (passby) takes the band only if the passed surface reads far
            banded = first & (plan.cos >= self.march.min_cos) & mask & raster
            t_band = torch.where(banded, plan.t_hit, torch.inf)
            passing = plan.passby & raster & torch.where(mask, banded, ~first)
            t_passing = torch.where(passing[:, None], torch.stack([plan.t_pass, plan.t_behind], 1), torch.inf)
            fd.views[v] = ViewData.compact(
                img, mask, b.hit.view(-1), b.near.view(-1), far, t_band, plan.cos.half(), t_passing
            )
            self.cache_seconds += time.perf_counter() - t0
        return fd.views[v]

    def rays_of(self, v: int) -> tuple[torch.Tensor, torch.Tensor]:
        """Origins and directions (H·W, 3) of view v's pixel rays (computed once)."""
        if v not in self.pixel_rays:
            self.pixel_rays[v] = self.capture.cameras[v].pixel_rays()
        return self.pixel_rays[v]

    def _batch(self, vd: ViewData, v: int, pix: torch.Tensor):
        """The rays of pixels ``pix`` (n,) of view v: origins, dirs, near, far, colour, mask,
        band hit, cosine, passing probes."""
        o, d = self.rays_of(v)
        near, far, t_band, cos, t_passing = vd.rays(pix)
        return (o[pix], d[pix], near, far, vd.colours(pix), vd.mask[pix].float(), t_band, cos, t_passing)

    def patch(self, fd: FrameData, t: int, v: int, p: int, gen: torch.Generator):
        """Rays of a random ``p``×``p`` patch inside the mask's bounding box of view v
        (clamped to the image); pixels whose ray misses the shell render the background."""
        vd = self.view(fd, t, v)
        cam = self.capture.cameras[v]
        w, h = cam.width, cam.height
        p = min(p, w, h)
        ys, xs = torch.nonzero(vd.mask.view(h, w), as_tuple=True)
        lo = (int(ys.min()), int(xs.min())) if len(ys) else (0, 0)
        hi = (int(ys.max()), int(xs.max())) if len(ys) else (h - 1, w - 1)
        corner = []
        for first, last, size in ((lo[0], hi[0], h), (lo[1], hi[1], w)):
            a = min(first, size - p)  # the patch starts inside the box and fits the image
            b = max(a, min(last - p + 1, size - p))
            corner.append(int(torch.randint(a, b + 1, (1,), generator=gen)))
        y0, x0 = corner
        yy, xx = torch.meshgrid(torch.arange(y0, y0 + p), torch.arange(x0, x0 + p), indexing="ij")
        pix = (yy * w + xx).reshape(-1)
        return self._batch(vd, v, pix)  # pixels whose ray misses the shell: background only

    def draw(self, fd: FrameData, t: int, v: int, n: int, gen: torch.Generator):
        """``n`` random rays of view v, ``train.fg_fraction`` of them inside the mask."""
        vd = self.view(fd, t, v)
        fg = torch.nonzero(vd.hit & vd.mask).squeeze(1)
        bg = torch.nonzero(vd.hit & ~vd.mask).squeeze(1)
        n_fg = min(len(fg), round(n * self.s.train.fg_fraction)) if len(bg) else min(len(fg), n)
        picks = [fg[torch.randint(len(fg), (n_fg,), generator=gen)]] if len(fg) else []
        if len(bg):
            picks.append(bg[torch.randint(len(bg), (n - n_fg,), generator=gen)])
        pix = torch.cat(picks)
        return self._batch(vd, v, pix)
