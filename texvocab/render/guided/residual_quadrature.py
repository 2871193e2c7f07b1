"""The residual rays' quadrature at render time, compiled
(:mod:`texvocab.render.kernels.quadrature_jit`): the columns of each ray's mesh samples
where the three field evaluations go (the ``residual.spread``, 1/2 and 1 - spread
quantiles of the weights the estimate ŝ = d + r0 gives them), and the ray's opacity,
colour, depth and ``ok`` from the evaluations (steps 2-3 of
:mod:`texvocab.render.guided.residual`). The torch reference, differentiable and used in
training, is :func:`~texvocab.render.guided.residual.grouped_quadrature`: on a trained
avatar its whole-array operations over the groups' padded arrays took a tenth of a frame
for a few hundred rays."""

from __future__ import annotations

import numpy as np
import torch

from texvocab.render.kernels.quadrature_jit import quadrature_columns, resolve
from texvocab.render.settings import MarchSettings
from texvocab.render.volume.field import evaluate_sdf, points_along
from texvocab.render.volume.volsdf import beta_value


def _f64(x: torch.Tensor) -> np.ndarray:
    return np.ascontiguousarray(x.detach().double().numpy())


def _cap(cap: float) -> float:
    """The shell width as the float32 samples meet it: torch compares ``d < cap`` in
    float32, where a sample beyond the shell reads exactly float32(cap)."""
    return float(np.float32(cap))


def knot_columns(t, d, count, r0, beta: float, cap: float, spread: float) -> torch.Tensor:
    """Columns (R, 3) long of the three evaluations for rays with mesh samples t, d (R, N)
    (the first count (R,) of each row), the probe's residual r0 (R, 1), β and the shell
    width ``cap``."""
    cols = np.empty((len(t), 3), np.int64)
    q = np.array([spread, 0.5, 1.0 - spread])
    n = count.numpy().astype(np.int64)
    quadrature_columns(_f64(t), _f64(d), n, _f64(r0).reshape(-1), beta, _cap(cap), q, cols)
    return torch.from_numpy(cols)


def resolve_rays(t, d, count, cols, knots, sdf3, rgb3, r0, beta, settings: MarchSettings):
    """Opacity (R,), colour (R, 3), depth (R,) (in t's dtype) and ok (R,) bool of rays with
    mesh samples t, d (R, N) (count (R,) each), their evaluations at columns cols (R, 3),
    knots (R, 3) reading SDF sdf3 (R, 3) and colour rgb3 (R, 3, 3), and the probe's
    residual r0 (R, 1)."""
    R = len(t)
    acc, depth = np.empty(R), np.empty(R)
    color, ok = np.empty((R, 3)), np.empty(R, np.bool_)
    resolve(
        _f64(t),
        _f64(d),
        count.numpy().astype(np.int64),
        cols.numpy(),
        _f64(knots),
        _f64(sdf3),
        _f64(rgb3),
        _f64(r0).reshape(-1),
        beta_value(beta),
        _cap(settings.shell.width),
        float(settings.residual.tolerance),
        acc,
        color,
        depth,
        ok,
    )
    dtype = t.dtype
    return (
        torch.from_numpy(acc).to(dtype),
        torch.from_numpy(color).to(dtype),
        torch.from_numpy(depth).to(dtype),
        torch.from_numpy(ok),
    )


def evaluate_knots(field, origin, dirs, rows, knots, knot_faces, settings: MarchSettings):
    """The field at the knots (n, 3) of rays ``rows`` (n,), with their known faces (n, 3)
    (None: searched): SDF (3n,), colour (3n, 3)."""
    o = origin if origin.dim() == 1 else origin[rows]
    return evaluate_sdf(
        field,
        points_along(o, dirs[rows], knots).reshape(-1, 3),
        dirs[rows].repeat_interleave(3, 0),
        settings.chunks.points,
        None if knot_faces is None else knot_faces.reshape(-1),
    )


def compiled_quadrature(field, origin, dirs, t, d, f, count, r0, beta, settings: MarchSettings):
    """:func:`texvocab.render.guided.residual.grouped_quadrature` without gradients,
    compiled, each ray over its own samples: the same arguments and returns."""
    cap = float(settings.shell.width)
    cols = knot_columns(t, d, count, r0, beta_value(beta), cap, settings.residual.spread)
    knots = t.gather(1, cols)
    knot_faces = f.gather(1, cols) if settings.surface_reuse else None
    sdf3, rgb3 = evaluate_knots(field, origin, dirs, torch.arange(len(dirs)), knots, knot_faces, settings)
    sdf3, rgb3 = sdf3.view(-1, 3), rgb3.view(-1, 3, 3)
    return knots, knot_faces, sdf3, resolve_rays(t, d, count, cols, knots, sdf3, rgb3, r0, beta, settings)
