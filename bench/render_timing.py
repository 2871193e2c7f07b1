"""Timing one neural frame (bench/render_speed.py, bench/frame_limits.py): a pose field
that adds up its own calls' time and points, the frame rendered with its stages split, the
uniform reference marcher on the same field, and the default render path as it was
(``BEFORE`` and the two context managers) beside today's in one run."""

from __future__ import annotations

import contextlib
import time

import numpy as np
import torch

#: the render knobs that give the default path as it was before the surface reuse, the
#: quadrature's ray groups, the coarser residual passes, the fallback's 64-scout steps, its
#: gridless march of a few rays, the misses probed across the whole shell and the retried
#: Newton bands (``previous`` of --compare; its misses were probed only within miss_margin β
#: of the mesh)
BEFORE = {
    "surface_reuse": False,
    "residual_groups": 1,
    "residual_levels": 0,
    "fallback_segment": 8,
    "fallback_grid_rays": 0,
    "miss_reach": "margin",
    "band_retries": 0,
}


class Timed:
    """A pose field whose calls (density or SDF) add their time and point count to
    ``spent``; ``beta`` passes through (the surface-guided marcher reads it)."""

    def __init__(self, field, spent: dict):
        self.field, self.spent = field, spent
        self.beta = field.beta

    @property
    def takes_known(self) -> bool:
        return getattr(self.field, "takes_known", False)

    def _timed(self, fn, points, dirs, **kw):
        start = time.perf_counter()
        out = fn(points, dirs, **kw)
        self.spent["field"] += time.perf_counter() - start
        self.spent["evals"] += len(points)
        return out

    def __call__(self, points, dirs):
        return self._timed(self.field, points, dirs)

    def sdf_rgb(self, points, dirs, **kw):
        return self._timed(self.field.sdf_rgb, points, dirs, **kw)


def timed_render(model, item, march):
    """Render one item with the time split; returns (image (H, W, 3) numpy, row dict)."""
    from texvocab.render import prepare_shell, render_image

    _, pose, trans, cam, _, _ = item
    spent = {"field": 0.0, "evals": 0}
    wall0, cpu0 = time.perf_counter(), time.process_time()
    with torch.no_grad():
        ctx = model.pose_feature.context(pose, trans)
        t1 = time.perf_counter()
        # the surface-guided marcher builds what it needs of the shell itself
        shell = prepare_shell(march, ctx.vertices, model.body.faces, index=ctx.index)
        t2 = time.perf_counter()
        out = render_image(
            Timed(model.for_pose(ctx, march.precision), spent),
            cam,
            ctx.vertices,
            model.body.faces,
            march,
            shell=shell,
            index=ctx.index,
        )
    t3 = time.perf_counter()
    row = {
        "context": t1 - wall0,
        "shell": t2 - t1,
        "field": spent["field"],
        "evals": spent["evals"],
        "march": t3 - t2 - spent["field"],
        "total": t3 - wall0,
        "cpu": time.process_time() - cpu0,
    }
    return out.rgb.numpy().astype(np.float32), row


def reference_render(model, item, coarse: int, fine: int):
    """The uniform reference marcher on the same field: (image, row dict)."""
    from texvocab.render import mesh_bbox, render_image_uniform

    _, pose, trans, cam, _, _ = item
    wall0, cpu0 = time.perf_counter(), time.process_time()
    with torch.no_grad():
        ctx = model.pose_feature.context(pose, trans)
        lo, hi = mesh_bbox(ctx.vertices, model.settings.shell_width)
        out = render_image_uniform(model.for_pose(ctx), cam, lo, hi, coarse, fine)
    total = time.perf_counter() - wall0
    return out.rgb.numpy().astype(np.float32), {
        "context": float("nan"),
        "shell": 0.0,
        "field": float("nan"),
        "evals": out.stats.field_evals,
        "march": float("nan"),
        "total": total,
        "cpu": time.process_time() - cpu0,
    }


@contextlib.contextmanager
def plain_softplus(model, plain: bool):
    """With ``plain``, the field's activations are torch's own nn.Softplus(β = 100) for the
    duration, as the field computed before :class:`~texvocab.method.field.NormalSoftplus`
    (the same function to float32 rounding, with subnormal numbers): today's paths as they
    were, beside the new one in the same run."""
    from torch import nn

    from texvocab.method.field import NormalSoftplus

    swapped = []
    if plain:
        for net in (model.sdf_net, model.color_net):
            for i, m in enumerate(net):
                if isinstance(m, NormalSoftplus):
                    net[i] = nn.Softplus(beta=m.beta, threshold=m.threshold)
                    swapped.append((net, i, m))
    try:
        yield
    finally:
        for net, i, m in swapped:
            net[i] = m


@contextlib.contextmanager
def plain_search(plain: bool):
    """With ``plain``, the mesh queries as they were for the duration (the ``previous``
    path): the closest-face kernel as it was
    (:func:`~texvocab.geometry._nearest_jit.nearest_faces_plain`: the same answers bit for
    bit, slower), and the residual rays' mesh samples placed by torch arrays padded to the
    longest ray (:func:`~texvocab.render.guided.residual.padded_mesh_samples`: the same
    samples, slower), and their quadrature in torch's groups of padded arrays
    (:func:`~texvocab.render.guided.residual.grouped_quadrature`: the same to float
    rounding, slower)."""
    from texvocab.geometry import _nearest_jit, surface
    from texvocab.render.guided import residual

    surface.nearest_faces = _nearest_jit.nearest_faces_plain if plain else _nearest_jit.nearest_faces
    residual.mesh_samples = residual.padded_mesh_samples if plain else residual.compiled_mesh_samples
    residual.quadrature_compiled = not plain
    try:
        yield
    finally:
        surface.nearest_faces = _nearest_jit.nearest_faces
        residual.mesh_samples = residual.compiled_mesh_samples
        residual.quadrature_compiled = True
