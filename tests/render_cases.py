"""Shared render-test cases: the shell width, PSNR, march settings and pixel rays of a
camera, used by the render, guided, band, residual and training-ray tests."""

import numpy as np
import torch

from texvocab.capture.camera import Camera
from texvocab.render import MarchSettings, plan_surface

DELTA = 0.04


def psnr(a: torch.Tensor, b: torch.Tensor) -> float:
    mse = float(((a - b) ** 2).mean())
    return float("inf") if mse == 0 else -10 * np.log10(mse)


def looking_away(camera: Camera) -> Camera:
    """The same camera centre, turned by 180° about its y axis."""
    R = np.diag([-1.0, 1.0, -1.0]) @ camera.R
    return Camera(camera.K, R, -R @ camera.center, camera.width, camera.height)


SHELL = MarchSettings.from_flat(shell_width=DELTA, coarse_samples=36, fine_samples=16, early_stop_eps=1e-4)
GUIDED = SHELL.replace(guide="raster")


MARCH = MarchSettings.from_flat(
    shell_width=DELTA, coarse_samples=36, fine_samples=16, early_stop_eps=0, segment=512, scout_threshold=None
)


def rays_of(body, camera):
    """Every pixel ray of ``camera`` that meets the shell: origins, dirs, near, far, and the
    plan's band hits and passing probes (inf where a ray is neither)."""
    bounds = body["shell"].image_bounds(camera)
    pix = torch.nonzero(bounds.hit.view(-1)).squeeze(1)
    o, d = camera.pixel_rays()
    plan = plan_surface(body["v"], body["f"], camera, d, DELTA, DELTA, MARCH.min_cos)
    t_band = torch.where(plan.band, plan.t_hit, torch.inf)
    passing = plan.passby & ~plan.hit
    t_pass = torch.where(passing[:, None], torch.stack([plan.t_pass, plan.t_behind], 1), torch.inf)
    return (
        o[pix],
        d[pix],
        bounds.near.view(-1)[pix],
        bounds.far.view(-1)[pix],
        t_band[pix],
        plan.cos[pix],
        t_pass[pix],
    )
