"""Where a rendered frame's and a training step's time goes, against the compute limit of
this machine measured in the same run.

The limit: dense matrix products at the machine's 2 threads, fp32 (sgemm) and bf16 (AMX
on Sapphire Rapids), both as a large square product and in the shape the field's MLPs
have (N points × 128 by 128 × 128). The field's work per point is its MLPs' multiply-adds
(:func:`field_flops`: 2 FLOP each; the pose's first-layer columns are folded into a bias
once per call, so they are not per point). Each stage of a frame of the surface-guided
marcher (the default render path) and of a training step is timed, with its field calls'
time and points, and set against the time its points' FLOPs would take at the limit:
``× limit`` = the stage's time / that time. On a CPU without bf16 units (no AMX or
AVX512-BF16 in /proc/cpuinfo) the bf16 rates read nan: torch emulates bf16 there. Stages
whose work is not matrix products (the raster, the mesh queries, the pose's set-up) have
no such limit: their share is what is left for the CPU's other work.

    .venv/bin/python bench/frame_limits.py CKPT [--frames 3] [--steps 20] [--warmup 40]
        [--repeats 2]

The stages are timed by wrapping the marcher's stage functions in this process only
(texvocab.render.guided.triage's ``_probe``, ``newton_band``, ``sample_band``,
``render_residual``; the image's plan, bounds and fallback march); the library is not
changed. Uses 2 threads with OMP_WAIT_POLICY=PASSIVE unless set otherwise.
"""

from __future__ import annotations

import argparse
import os
import time
from collections import defaultdict
from contextlib import contextmanager

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # before torch loads OpenMP

import torch  # noqa: E402
from torch import nn  # noqa: E402

from texvocab.blas import budget_blas_threads  # noqa: E402


def gemm_gflops(m: int, k: int, n: int, dtype: torch.dtype, seconds: float = 0.6) -> float:
    """GFLOP/s of (m, k) @ (k, n) in ``dtype``, best of repeated runs over ``seconds``."""
    a, b = torch.randn(m, k).to(dtype), torch.randn(k, n).to(dtype)
    for _ in range(2):
        a @ b
    best, end = float("inf"), time.perf_counter() + seconds
    while time.perf_counter() < end:
        t0 = time.perf_counter()
        a @ b
        best = min(best, time.perf_counter() - t0)
    return 2.0 * m * k * n / best / 1e9


def machine_limits(seconds: float = 0.6) -> dict[str, float]:
    """GFLOP/s: square 2048³ products and the field's shape (23k × 128 by 128 × 128),
    each the best over ``seconds`` of repeats."""
    from texvocab.method.field_precision import native_bfloat16

    # where the CPU has no bf16 units torch emulates them at a few GFLOP/s (a 2048³
    # product then takes minutes): not a limit the field would run at (render.precision
    # auto keeps float32 there), so not measured
    native = native_bfloat16()
    return {
        "sgemm": gemm_gflops(2048, 2048, 2048, torch.float32, seconds),
        "bf16": gemm_gflops(2048, 2048, 2048, torch.bfloat16, seconds) if native else float("nan"),
        "sgemm_mlp": gemm_gflops(23000, 128, 128, torch.float32, seconds),
        "bf16_mlp": gemm_gflops(23000, 128, 128, torch.bfloat16, seconds) if native else float("nan"),
    }


def field_flops(model) -> float:
    """FLOP per point of the field's MLPs (2 per multiply-add), without the pose's
    first-layer columns (folded into a bias once per call: AvatarField._sdf_hidden)."""
    total = 0
    nets = (model.feature_proj, model.sdf_net, model.color_net)
    for net in nets:
        for m in net.modules() if isinstance(net, nn.Sequential) else [net]:
            if isinstance(m, nn.Linear):
                total += m.in_features * m.out_features
    pose_cols = 4 * model.body.num_joints * model.settings.hidden
    return 2.0 * (total - pose_cols)


class Stages:
    """Wall time, field time and field points per named stage, for wrapped functions."""

    def __init__(self):
        self.seconds: dict[str, float] = defaultdict(float)
        self.field_s: dict[str, float] = defaultdict(float)
        self.points: dict[str, int] = defaultdict(int)
        self.current: list[str] = []

    def wrap(self, name: str, fn):
        """``fn`` timed as stage ``name``, exclusive of the stages called inside it (whose
        time the stage around them loses: the fallback march builds the shell bounds, the
        render calls every stage)."""

        def timed(*args, **kwargs):
            self.current.append(name)
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                spent = time.perf_counter() - t0
                self.seconds[name] += spent
                self.current.pop()
                if self.current:
                    self.seconds[self.current[-1]] -= spent

        return timed

    def field_call(self, fn, points):
        t0 = time.perf_counter()
        out = fn()
        name = self.current[-1] if self.current else "other"
        self.field_s[name] += time.perf_counter() - t0
        self.points[name] += len(points)
        return out


@contextmanager
def staged(stages: Stages):
    """Wrap the guided marcher's stage functions and every pose field's calls."""
    from texvocab.method import field as field_mod
    from texvocab.render.guided import image, triage

    saved = []

    def patch(owner, attr, name):
        saved.append((owner, attr, getattr(owner, attr)))
        setattr(owner, attr, stages.wrap(name, getattr(owner, attr)))

    patch(triage, "_probe", "probe")
    patch(triage, "newton_band", "band")
    patch(triage, "sample_band", "band")
    patch(triage, "render_residual", "residual")
    patch(image, "plan_surface", "plan (raster)")
    patch(image.GuidedImage, "_shell_bounds", "shell bounds")
    patch(image.GuidedImage, "_fallback", "fallback march")
    patch(triage, "render_rays", "fallback march")
    pf = field_mod.PoseField
    call, sdf_rgb = pf.__call__, pf.sdf_rgb
    pf.__call__ = lambda self, p, d: stages.field_call(lambda: call(self, p, d), p)
    pf.sdf_rgb = lambda self, p, d, **kw: stages.field_call(lambda: sdf_rgb(self, p, d, **kw), p)
    try:
        yield stages
    finally:
        pf.__call__, pf.sdf_rgb = call, sdf_rgb
        for owner, attr, fn in reversed(saved):
            setattr(owner, attr, fn)


def frame_stages(
    model,
    settings,
    capture,
    frames: int,
    repeats: int,
    *extra: str,
    size: int | None = None,
    plain: bool = False,
):
    """Per-frame means of each stage of the default render path (guided, ``fast`` knobs,
    with the render knobs ``extra`` as ``name=value``: MarchSettings' flat names; ``plain``:
    the closest-face search's kernel as it was, render_speed.plain_search)."""
    from render_speed import _value, items_of, resized  # bench/ sibling
    from render_timing import plain_search

    from texvocab.pipeline.settings import PRESETS, march_settings
    from texvocab.render import render_image

    knobs = [f"{k}={v}" for k, v in PRESETS["fast"].items() if k != "image_scale"]
    march = march_settings(settings.with_overrides(knobs + ["guide=raster"]))
    march = march.replace(**{k: _value(v) for k, v in (e.split("=", 1) for e in extra)})
    items = resized(items_of(capture, settings, frames), size)
    best = None
    for _ in range(max(repeats, 1)):
        st = Stages()
        with staged(st), torch.no_grad(), plain_search(plain):
            t0 = time.perf_counter()
            for _, pose, trans, cam, _, _ in items:
                ctx = st.wrap("pose context", model.pose_feature.context)(pose, trans)
                st.wrap("render other", render_image)(
                    model.for_pose(ctx, march.precision),
                    cam,
                    ctx.vertices,
                    model.body.faces,
                    march,
                    index=ctx.index,
                )
            total = time.perf_counter() - t0
        if best is None or total < best[0]:
            best = (total, st)
    total, st = best
    return st, total, len(items), f"{len(items)} frames at {items[0][3].width}x{items[0][3].height}"


def step_stages(capture, settings, steps: int, warmup: int, out_dir: str):
    """Per-step means of a training step's stages (forward stages, backward, optimiser)."""
    from texvocab.pipeline.train import Trainer

    trainer = Trainer(capture, settings, out_dir, progress=False)
    for _ in range(warmup):  # first draws build the frames' caches: not timed
        trainer.train_step()
    st = Stages()
    loss_terms, backward = trainer.loss_terms, torch.Tensor.backward
    trainer.loss_terms = st.wrap("forward other", loss_terms)
    trainer._eikonal = st.wrap("eikonal (its points uncounted)", trainer._eikonal)
    torch.Tensor.backward = st.wrap("backward", backward)
    t0 = time.perf_counter()
    with staged(st):
        try:
            for _ in range(steps):
                trainer.train_step()
        finally:
            torch.Tensor.backward = backward
    total = time.perf_counter() - t0
    return st, total, steps, trainer.model


def table(st: Stages, total: float, n: int, flop: float, limits: dict, backward: bool = False) -> None:
    """Print the stage table, per frame (or step); each stage's time excludes the stages
    nested in it (Stages.wrap)."""
    order = [k for k in st.seconds] + [k for k in st.field_s if k not in st.seconds]
    print("| stage | ms | field ms | field points | GFLOP | ms at sgemm / bf16 | × sgemm limit |")
    print("|---|---|---|---|---|---|---|")
    rate32, rate16 = limits["sgemm_mlp"] * 1e9, limits["bf16_mlp"] * 1e9
    for name in order:
        sec = st.seconds.get(name, 0.0)  # exclusive of the stages inside it
        pts = st.points.get(name, 0) / n
        # the backward pass of a step multiplies the forward's products by about 2
        fl = (
            (2.0 if name == "backward" else 1.0)
            * flop
            * (sum(st.points.values()) / n if name == "backward" else pts)
        )
        lim = (
            f"{fl / rate32 * 1e3:.1f} / {fl / rate16 * 1e3:.1f} | {sec / n / (fl / rate32):.0f}×"
            if fl
            else "— | —"
        )
        print(
            f"| {name} | {sec / n * 1e3:.1f} | {st.field_s.get(name, 0.0) / n * 1e3:.1f} | "
            f"{pts:,.0f} | {fl / 1e9:.3f} | {lim} |"
        )
    all_pts = sum(st.points.values()) / n
    fl = flop * all_pts * (3.0 if backward else 1.0)
    print(
        f"| **total** | **{total / n * 1e3:.1f}** | {sum(st.field_s.values()) / n * 1e3:.1f} | "
        f"{all_pts:,.0f} | {fl / 1e9:.3f} | {fl / rate32 * 1e3:.1f} / {fl / rate16 * 1e3:.1f} | "
        f"{total / n / (fl / rate32):.0f}× |\n"
    )


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("checkpoint")
    p.add_argument("--frames", type=int, default=3)
    p.add_argument("--repeats", type=int, default=2, help="frame passes; the fastest is kept")
    p.add_argument("--steps", type=int, default=20, help="timed training steps (0: none)")
    p.add_argument("--warmup", type=int, default=40, help="untimed training steps first")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--gemm-seconds", type=float, default=0.6, help="time spent on each GEMM rate")
    p.add_argument(
        "--before",
        default=None,
        metavar="KNOB=VALUE,...",
        help="also time the frame with these render knobs (e.g. surface_reuse=false) and the "
        "closest-face kernel as it was, in the same run, passes alternating: a before and an "
        "after table",
    )
    p.add_argument("--size", type=int, default=None, help="render at N x N (the cameras scaled)")
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)
    budget_blas_threads(1)
    import tempfile

    from texvocab.pipeline import load_avatar

    av = load_avatar(args.checkpoint, progress=False)
    model = av.model.eval()
    flop = field_flops(model)
    limits = machine_limits(args.gemm_seconds)
    print(f"# where the time goes, against the compute limit\n\n{torch.get_num_threads()} threads.\n")
    print("| limit | GFLOP/s |\n|---|---|")
    print(f"| sgemm 2048³ | {limits['sgemm']:.0f} |\n| bf16 GEMM 2048³ | {limits['bf16']:.0f} |")
    print(f"| sgemm 23000×128 · 128×128 (the MLPs' shape) | {limits['sgemm_mlp']:.0f} |")
    print(f"| bf16 23000×128 · 128×128 | {limits['bf16_mlp']:.0f} |\n")
    print(f"The field's MLPs: {flop / 1e6:.3f} MFLOP per point.\n")
    if args.before:
        before = args.before.split(",")
        best = {}
        for _ in range(max(args.repeats, 1)):  # alternate, so both see the same machine
            for name, extra in (("before", before), ("after", [])):
                got = frame_stages(
                    model,
                    av.settings,
                    av.capture,
                    args.frames,
                    1,
                    *extra,
                    size=args.size,
                    plain=name == "before",
                )
                if name not in best or got[1] < best[name][1]:
                    best[name] = got
        for name, extra in (("before", before), ("after", [])):
            st, total, n, what = best[name]
            knobs = ", ".join(extra) or "the defaults"
            print(f"## a frame, {name} ({what}; guided marcher, `fast` knobs, {knobs}; per frame)\n")
            table(st, total, n, flop, limits)
    else:
        st, total, n, what = frame_stages(
            model, av.settings, av.capture, args.frames, args.repeats, size=args.size
        )
        print(f"## a frame ({what}; guided marcher, `fast` knobs; per frame)\n")
        table(st, total, n, flop, limits)
    frame_s = total / n
    rates = f"sgemm_gflops={limits['sgemm']:.0f} bf16_gflops={limits['bf16']:.0f}"
    if args.steps:
        with tempfile.TemporaryDirectory() as tmp:
            st, total, n, tmodel = step_stages(av.capture, av.settings, args.steps, args.warmup, tmp)
        print(f"## a training step ({av.settings.train.rays_per_batch} rays; per step, {n} steps)\n")
        table(st, total, n, field_flops(tmodel), limits, backward=True)
        print(f"summary: frame_s={frame_s:.3f} step_s={total / n:.3f} {rates}")
    else:
        print(f"summary: frame_s={frame_s:.3f} {rates}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
