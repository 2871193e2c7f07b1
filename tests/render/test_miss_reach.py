"""Surface off the mesh: the guided marcher's rays that miss the posed mesh but pass within
the shell (``miss_reach``), the case of loose clothing, whose surface stands centimetres
outside the body's silhouette where the mesh says there is nothing."""

import torch
from render_cases import GUIDED, SHELL

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
