"""How exact is the eikonal term's gradient? Training's autograd gradient of the SDF
against central finite differences of the whole SDF, on the points the eikonal term draws.

    .venv/bin/python bench/eikonal_gradient.py CKPT [CKPT ...] [--frames 4] [--points 512]
        [--eps 1e-4 1e-3] [--seed 0]

The avatar's SDF at x is the posed body's distance plus the SDF network's residual of
(γ(x_c), f(Θ, x)). Training differentiates it by autograd
(:meth:`~texvocab.method.field.AvatarField.sdf_and_color`): the body distance has its
analytic gradient, but the texture feature f and the skinning weights that canonicalise x
come from the closest point on the posed mesh, a search without a gradient, so their
change with x is left out. Finite differences re-run the search at x ± ε along each axis,
so they see the whole SDF. Points as ``Trainer._eikonal`` draws them: mesh vertices plus
Gaussian noise of σ = δ/2, on training frames spread through the capture.

Rows per checkpoint and ε: mean |∇| both ways, the mean angle between the two gradients,
the relative difference |g_autograd − g_fd| / |g_fd| (median and 90th percentile), and the
eikonal term mean((|∇| − 1)²) both ways, and the share of points where the finite
differences read |∇| > 2 (the SDF jumps there: the closest point changed face, or the
feature crossed a UV seam) with the finite-difference term without them. The last line
printed is ``summary: rel_median=… angle_deg=… eikonal_autograd=… eikonal_fd=…`` for the
first checkpoint at the first ε.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
import torch

from texvocab.pipeline.avatar import load_avatar
from texvocab.pipeline.evaluate import spread


def gradients(model, ctx, pts: torch.Tensor, eps: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(autograd (N, 3), finite differences (N, 3), valid (N,)) gradients of the SDF."""
    x = pts.clone().requires_grad_(True)
    dirs = torch.nn.functional.normalize(torch.randn_like(pts), dim=-1)
    sdf, _, valid = model.sdf_and_color(ctx, x, dirs)
    (g_auto,) = torch.autograd.grad(sdf.sum(), x)
    g_fd = torch.zeros_like(pts)
    ok = valid.clone()
    with torch.no_grad():
        for axis in range(3):
            step = torch.zeros(3)
            step[axis] = eps
            hi, _, v_hi = model.sdf_and_color(ctx, pts + step, dirs)
            lo, _, v_lo = model.sdf_and_color(ctx, pts - step, dirs)
            g_fd[:, axis] = (hi.double() - lo.double()).float() / (2 * eps)
            ok &= v_hi & v_lo
    return g_auto.numpy(), g_fd.numpy(), ok.numpy()


def measure(ckpt: str, frames: int, points: int, eps: float, seed: int) -> dict:
    avatar = load_avatar(ckpt, progress=False)
    model, cap = avatar.model, avatar.capture
    gen = torch.Generator().manual_seed(seed)
    rows = []
    for t in spread(list(range(cap.num_train)), frames):
        with torch.no_grad():
            ctx = model.pose_feature.context(cap.poses[t], cap.trans[t])
        verts = ctx.vertices.detach()
        idx = torch.randint(len(verts), (points,), generator=gen)
        noise = torch.randn(points, 3, generator=gen) * (model.settings.shell_width / 2)
        rows.append(gradients(model, ctx, verts[idx] + noise, eps))
    g_a = np.concatenate([r[0] for r in rows])
    g_f = np.concatenate([r[1] for r in rows])
    ok = np.concatenate([r[2] for r in rows])
    g_a, g_f = g_a[ok], g_f[ok]
    n_a, n_f = np.linalg.norm(g_a, axis=1), np.linalg.norm(g_f, axis=1)
    cos = (g_a * g_f).sum(1) / np.maximum(n_a * n_f, 1e-12)
    rel = np.linalg.norm(g_a - g_f, axis=1) / np.maximum(n_f, 1e-12)
    return {
        "points": int(ok.sum()),
        "norm_autograd": float(n_a.mean()),
        "norm_fd": float(n_f.mean()),
        "angle_deg": float(np.degrees(np.arccos(np.clip(cos, -1, 1))).mean()),
        "rel_median": float(np.median(rel)),
        "rel_p90": float(np.percentile(rel, 90)),
        "eikonal_autograd": float(((n_a - 1) ** 2).mean()),
        "eikonal_fd": float(((n_f - 1) ** 2).mean()),
        "beta_mm": float(model.beta.detach()) * 1000,
        "jumps": float((n_f > 2).mean()),
        "eikonal_fd_smooth": float(((n_f[n_f <= 2] - 1) ** 2).mean()),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("checkpoints", nargs="+")
    ap.add_argument("--frames", type=int, default=4)
    ap.add_argument("--points", type=int, default=512)
    ap.add_argument("--eps", type=float, nargs="+", default=[1e-4, 1e-3])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    torch.manual_seed(args.seed)
    print(
        "| checkpoint | β (mm) | ε (m) | points | mean abs ∇ autograd | finite diff. | angle (°) | "
        "rel. diff. median | p90 | eikonal autograd | finite diff. | share with fd abs ∇ > 2 | "
        "fd eikonal without them |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    first = None
    for ckpt in args.checkpoints:
        for eps in args.eps:
            r = measure(ckpt, args.frames, args.points, eps, args.seed)
            first = first or r
            print(
                f"| {ckpt} | {r['beta_mm']:.2f} | {eps:g} | {r['points']} | {r['norm_autograd']:.3f} | "
                f"{r['norm_fd']:.3f} | {r['angle_deg']:.2f} | {r['rel_median']:.4f} | {r['rel_p90']:.4f} | "
                f"{r['eikonal_autograd']:.4f} | {r['eikonal_fd']:.4f} | {r['jumps']:.3f} | "
                f"{r['eikonal_fd_smooth']:.4f} |",
                flush=True,
            )
    print(
        f"summary: rel_median={first['rel_median']:.4f} angle_deg={first['angle_deg']:.2f} "
        f"eikonal_autograd={first['eikonal_autograd']:.4f} eikonal_fd={first['eikonal_fd']:.4f}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
