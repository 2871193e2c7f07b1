"""Surface off the mesh: the guided marcher's rays that miss the posed mesh but pass within
the shell (``miss_reach``), the case of loose clothing, whose surface stands centimetres
outside the body's silhouette where the mesh says there is nothing."""

import torch
from render_cases import GUIDED, SHELL, psnr

from texvocab.render import render_image
from texvocab.render.analytic import MeshResidualField

OFFSET = 0.03  # the surface stands 3 cm outside the mesh, inside the 4 cm shell


class InflatedField(MeshResidualField):
    """The mesh's signed distance minus OFFSET: the mesh inflated by 3 cm."""

    def residual(self, points: torch.Tensor) -> torch.Tensor:
        return torch.full_like(points[:, 0], -OFFSET)


def test_a_surface_outside_the_mesh_silhouette_is_rendered_as_the_shell_marcher_renders_it(body):
    v, f = body["v"], body["f"]
    cam = body["camera"].scaled(4.0)  # 256²: the 3 cm rim is about three pixels wide
    field = InflatedField(v, f, beta=0.0005)
    with torch.no_grad():
        truth = render_image(field, cam, v, f, SHELL, shell=body["shell"])
        exact = render_image(field, cam, v, f, GUIDED, shell=body["shell"])
        margin = render_image(field, cam, v, f, GUIDED.replace(miss_reach="margin"), shell=body["shell"])
    solid = truth.alpha > 0.5
    rim = int(solid.sum()) - int((margin.alpha > 0.5).sum())
    assert rim > 0.1 * int(solid.sum())  # the margin reach loses the rim ...
    assert int(((exact.alpha > 0.5) != solid).sum()) < 0.02 * int(solid.sum())  # ... the shell keeps it
    assert (exact.alpha - truth.alpha).abs().mean() < 0.01


class ClothField(InflatedField):
    """Cloth 3 cm off the mesh whose residual relaxes towards the body (-1 cm on the mesh):
    one Newton step from the mesh hit lands short of it, where the three evaluations'
    residuals disagree; a second from there lands on it."""

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        d = super().sdf(points) + OFFSET  # the mesh distance (capped beyond the band)
        cloth = d - OFFSET + 0.02 * torch.exp(-d.clamp(min=0) / 0.005)
        return torch.where(d < self.band, cloth, torch.full_like(d, self.band))


def cloth_renders(body, knob: str):
    """The cloth field at 128²: the shell marcher's image, and the guided marcher's with
    ``knob`` (a retry count) at 0 and at 1."""
    v, f = body["v"], body["f"]
    cam = body["camera"].scaled(2.0)
    field = ClothField(v, f, beta=0.002)
    with torch.no_grad():
        return [
            render_image(field, cam, v, f, march, shell=body["shell"])
            for march in (SHELL, GUIDED.replace(**{knob: 0}), GUIDED.replace(**{knob: 1}))
        ]


def test_a_newton_band_retried_from_its_newton_point_resolves_cloth_off_the_body(body):
    truth, once, retried = cloth_renders(body, "band_retries")
    assert retried.stats.paths["band"] > once.stats.paths["band"] + 0.3 * int((truth.alpha > 0.5).sum())
    assert retried.stats.field_evals < 0.7 * once.stats.field_evals
    # the marched rays (once) and the retried bands give the same image to about 50 dB
    assert psnr(once.rgb, truth.rgb) > 50 and psnr(retried.rgb, truth.rgb) > 50


def test_a_residual_ray_retried_from_its_evaluations_resolves_cloth_off_the_body(body):
    """Misses past the cloth's edge read the residual at their closest approach to the
    body, not where they meet the cloth: the first try's three evaluations disagree, and
    a second try from them resolves the ray instead of the marcher."""
    truth, once, retried = cloth_renders(body, "residual_retries")
    assert retried.stats.paths["fallback"] < 0.3 * once.stats.paths["fallback"]
    assert retried.stats.field_evals < 0.5 * once.stats.field_evals
    assert psnr(once.rgb, truth.rgb) > 50 and psnr(retried.rgb, truth.rgb) > 50
