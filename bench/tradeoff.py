"""The speed-accuracy dial, measured: sweeps every render knob of a trained avatar (image
scale, coarse and fine samples per ray, shell width δ, early-termination ε) one at a
time from the defaults, plus the presets, and reports

- seconds per frame (median over the images), field evaluations per frame;
- PSNR/SSIM against the capture's ground truth (mask bounding box; renders at a reduced
  image scale are upsampled bilinearly to the full size first, as a viewer shows them);
- PSNR against a high-quality reference render of the same avatar (64+32 samples, no
  early termination), which isolates the renderer's error from the model's;

then writes a Pareto plot (seconds vs PSNR, presets marked) and two cost-growth tables:
seconds per frame vs image size, and the method's data-side costs (texture maps,
vocabulary build/query, pose-feature cost) vs the number of training frames, M and K.

    .venv/bin/python bench/tradeoff.py [CKPT] [--out out/bench/tradeoff] [--per-set 2]

Without CKPT it uses the demo avatar (out/demo/avatar/checkpoint.pt, made by
``texvocab demo``) or trains one for ``--train-minutes`` on the default synthetic capture.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

from texvocab.blas import budget_blas_threads
from texvocab.io.images import atomic_write_bytes
from texvocab.metrics import metrics_in_bbox, psnr
from texvocab.pipeline.evaluate import render_view
from texvocab.pipeline.settings import PRESETS, RENDER_KNOBS
from texvocab.render import MarchSettings, ShellSettings

REFERENCE = {"coarse_samples": 64, "fine_samples": 32, "early_stop_eps": 0.0, "guide": "shell"}

# (label, overrides of the render knobs); one knob at a time from the defaults.
SWEEP: list[tuple[str, dict]] = (
    [(f"image_scale={v}", {"image_scale": v}) for v in (0.25, 0.5, 0.75)]
    + [(f"coarse={v}", {"coarse_samples": v}) for v in (6, 9, 12, 24, 36)]
    + [(f"fine={v}", {"fine_samples": v}) for v in (0, 4, 16)]
    + [(f"eps={v:g}", {"early_stop_eps": v}) for v in (0.0, 1e-2, 5e-2)]
    + [(f"shell={v}", {"shell_width": v}) for v in (0.02, 0.025, 0.03)]
    + [
        ("shell=0.025 8+4", {"shell_width": 0.025, "coarse_samples": 8, "fine_samples": 4}),
        ("shell=0.025 13+8", {"shell_width": 0.025, "coarse_samples": 13}),
    ]
    # the surface-guided marcher's own knobs (MarchSettings; with the defaults they
    # decide what a frame costs, the knobs above only act on the rays it still marches)
    + [(f"residual_step={v}", {"residual_step": v}) for v in (0.75, 3.0)]
    + [(f"residual_spread={v}", {"residual_spread": v}) for v in (0.02, 0.15)]
    + [(f"residual_tolerance={v}", {"residual_tolerance": v}) for v in (0.5, 8.0)]
    + [
        ("residual_rays=false", {"residual_rays": False}),
        ("band_newton=false", {"band_newton": False}),
        ("residual_rays=false band_newton=false", {"residual_rays": False, "band_newton": False}),
    ]
    + [(f"band_spacing={v}", {"band_spacing": v}) for v in (1.0, 3.0)]
    + [(f"miss_margin={v}", {"miss_margin": v}) for v in (6.0, 10.0)]
)
GUIDED_KNOBS = {
    "residual_rays",
    "residual_step",
    "residual_spread",
    "residual_tolerance",
    "band_newton",
    "band_spacing",
    "band_samples",
    "miss_margin",
    "min_cos",
}


def march_of(knobs: dict, base: MarchSettings) -> MarchSettings:
    keys = {"coarse_samples", "fine_samples", "early_stop_eps", "shell_width", "guide"} | GUIDED_KNOBS
    m = base.replace(**{k: v for k, v in knobs.items() if k in keys})
    if "shell_scale" in knobs and "shell_width" not in knobs:  # a preset's share of the field's shell
        m = m.replace(shell_width=knobs["shell_scale"] * base.shell_width)
    if m.guide == "shell" and base.guide != "shell":  # the shell marcher's own shell grid
        m = m.replace(shell_voxel=ShellSettings.voxel, shell_exact=ShellSettings.exact)
    return m


def measure(model, items, knobs: dict, base: MarchSettings, references=None) -> dict:
    march = march_of(knobs, base)
    scale = float(knobs.get("image_scale", 1.0))
    secs, evals, p_gt, s_gt, p_ref, images = [], [], [], [], [], []
    for i, (pose, trans, cam, gt, mask) in enumerate(items):
        rgb, stats = render_view(model, pose, trans, cam, march, scale)
        s, n = stats.seconds, stats.field_evals
        m = metrics_in_bbox(rgb, gt, mask)
        secs.append(s)
        evals.append(n)
        p_gt.append(m["psnr"])
        s_gt.append(m["ssim"])
        images.append(rgb)
        if references is not None:
            from texvocab.metrics.image import crop_to_bbox, mask_bbox

            box = mask_bbox(mask)
            p_ref.append(psnr(crop_to_bbox(rgb, box), crop_to_bbox(references[i], box)))
    return {
        "seconds": float(np.median(secs)),
        "evals": float(np.mean(evals)),
        "psnr_gt": float(np.mean(p_gt)),
        "ssim_gt": float(np.mean(s_gt)),
        "psnr_ref": float(np.mean(p_ref)) if p_ref else None,
        "images": images,
    }


def pareto(rows: list[dict]) -> set[str]:
    """Labels of the settings no other setting beats in both seconds and PSNR vs truth."""
    keep = set()
    for r in rows:
        if not any(
            o["seconds"] <= r["seconds"]
            and o["psnr_gt"] >= r["psnr_gt"]
            and (o["seconds"] < r["seconds"] or o["psnr_gt"] > r["psnr_gt"])
            for o in rows
        ):
            keep.add(r["label"])
    return keep


def plot(rows: list[dict], front: set[str], path: Path, title: str) -> Path:
    """Two panels over seconds per frame: PSNR against the ground truth (what a user sees;
    the model's error dominates) and against the 64+32 reference render (the renderer's
    own error). Presets are stars (orange: with the shell marcher); the Pareto front (vs
    truth) is dashed; the dotted line is the 1 s frame budget. Only the presets, the
    default, the reference, the image-scale points (and on the right the coarse-sample
    sweep) are labelled, to keep it readable."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker  # noqa: F401  (matplotlib.ticker.NullFormatter below)

    fig, axes = plt.subplots(1, 2, figsize=(13, 5.5), dpi=110)
    for ax, key, ylabel in (
        (axes[0], "psnr_gt", "PSNR vs ground truth, mask bbox (dB)"),
        (axes[1], "psnr_ref", "PSNR vs the 64+32 ε=0 reference render (dB)"),
    ):
        shown = [r for r in rows if r.get(key) is not None]
        for r in shown:
            preset = r["label"].startswith("preset ")
            ax.scatter(
                r["seconds"],
                r[key],
                s=110 if preset else 28,
                marker="*" if preset else "o",
                zorder=3 if preset else 2,
                color=("darkorange" if "guide=shell" in r["label"] else "crimson")
                if preset
                else ("tab:blue" if r["label"] in front else "grey"),
            )
            label = r["label"]
            if (
                preset
                or "scale" in label
                or label.startswith(("reference", "default"))
                or (key == "psnr_ref" and label.startswith("coarse"))
            ):
                ax.annotate(
                    r["label"],
                    (r["seconds"], r[key]),
                    fontsize=7,
                    xytext=(4, 3),
                    textcoords="offset points",
                    rotation=20,
                )
        if key == "psnr_gt":
            pts = sorted((r["seconds"], r[key]) for r in shown if r["label"] in front)
            ax.plot(
                [p[0] for p in pts], [p[1] for p in pts], "--", color="tab:blue", lw=1, label="Pareto front"
            )
            ax.legend(loc="lower right", fontsize=8)
        ax.axvline(1.0, color="black", lw=0.8, ls=":", zorder=1)  # the one-second frame budget
        ax.set_xscale("log")
        ticks = [
            t
            for t in (0.25, 0.5, 1, 2, 4, 8, 16)
            if min(r["seconds"] for r in shown) / 1.3 <= t <= max(r["seconds"] for r in shown) * 1.3
        ]
        ax.set_xticks(ticks, [f"{t:g} s" for t in ticks])
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xlabel("seconds per frame (median, 2 CPU cores)")
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", alpha=0.3)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()

    def write(tmp):
        fig.savefig(tmp, format="png")

    atomic_write_bytes(path, write)
    plt.close(fig)
    return path


def size_growth(model, item, base: MarchSettings) -> list[str]:
    pose, trans, cam, _, _ = item
    lines = [
        "| image | pixels | s/frame | field evals | s per 10⁴ px | × full-size time |",
        "|---|---|---|---|---|---|",
    ]
    rows = []
    for scale in (0.25, 0.5, 1.0, 2.0):
        c = cam.scaled(scale) if scale != 1.0 else cam
        _, stats = render_view(model, pose, trans, c, base)
        rows.append((c.width, c.height, stats.seconds, stats.field_evals))
    ref = next(r[2] for r in rows if r[0] == cam.width)
    for w, h, s, n in rows:
        lines.append(f"| {w}×{h} | {w * h} | {s:.3f} | {n} | {s / (w * h) * 1e4:.4f} | {s / ref:.2f} |")
    return lines


def data_growth(capture, model) -> list[str]:
    """Costs that grow with the training set and the vocabulary."""
    from texvocab.method.feature import PoseFeature
    from texvocab.method.texmap import build_texture_map
    from texvocab.method.vocab import Vocabulary

    poses = capture.poses[: capture.num_train]
    sampled = min(3, capture.num_train)  # a map's cost from the first training frames
    t0 = time.perf_counter()
    for t in range(sampled):
        build_texture_map(capture, t)
    per_map = (time.perf_counter() - t0) / sampled
    lines = [
        "| training frames T | M | K | texture maps (s, est.) | vocab build (s) | "
        "query (ms) | pose feature, 20k points (s) |",
        "|---|---|---|---|---|---|---|",
    ]
    pts = None
    for T, M, K in (
        (18, 20, 3),
        (36, 20, 3),
        (72, 20, 3),
        (72, 5, 3),
        (72, 10, 3),
        (72, 40, 3),
        (72, 20, 1),
        (72, 20, 5),
    ):
        if T > len(poses) or M > T:
            continue
        t0 = time.perf_counter()
        vocab = Vocabulary.build(poses[:T], "part", M, K)
        build_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        for _ in range(20):
            vocab.query(poses[-1])
        query_ms = (time.perf_counter() - t0) / 20 * 1e3
        pf = PoseFeature(model.body, vocab, model.pose_feature.textures, model.pose_feature.encoder)
        with torch.no_grad():
            ctx = pf.context(poses[-1], capture.trans[len(poses) - 1])
            if pts is None:
                g = torch.Generator().manual_seed(0)
                idx = torch.randint(0, len(ctx.vertices), (20000,), generator=g)
                pts = torch.as_tensor(ctx.vertices, dtype=torch.float32)[idx]
                pts = pts + 0.01 * torch.randn(pts.shape, generator=g)
            t0 = time.perf_counter()
            pf(ctx, pts)
            feat_s = time.perf_counter() - t0
        lines.append(
            f"| {T} | {M} | {K} | {per_map * T:.1f} | {build_s:.3f} | {query_ms:.2f} | {feat_s:.3f} |"
        )
    return lines


def load_or_train(args):
    from texvocab.capture import open as open_capture
    from texvocab.pipeline import load_avatar

    ckpt = Path(args.checkpoint) if args.checkpoint else Path("out/demo/avatar/checkpoint.pt")
    if not ckpt.is_file():
        from texvocab.cli.demo import demo_avatar, demo_capture

        root, _ = demo_capture("out/demo")
        ckpt, _ = demo_avatar("out/demo", root, args.train_minutes)
    av = load_avatar(ckpt, open_capture(args.capture) if args.capture else None)
    return ckpt, av.capture, av.model, av.settings, av.checkpoint


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("checkpoint", nargs="?", default=None)
    ap.add_argument("--capture", default=None, help="default: the checkpoint's capture")
    ap.add_argument("--out", default="out/bench/tradeoff")
    ap.add_argument("--per-set", type=int, default=2, help="frames per set (x 2 views)")
    ap.add_argument("--train-minutes", type=float, default=5.0)
    ap.add_argument(
        "--plot-only",
        action="store_true",
        help="redraw OUT/pareto.png from OUT/tradeoff.json without measuring",
    )
    args = ap.parse_args(argv)
    if args.plot_only:
        rows = json.loads((Path(args.out) / "tradeoff.json").read_text())
        print(plot(rows, pareto(rows), Path(args.out) / "pareto.png", str(args.out)))
        return 0
    torch.set_num_threads(2)
    budget_blas_threads(1)  # as the texvocab command does (texvocab/blas.py)

    from texvocab.pipeline.evaluate import build_sets
    from texvocab.pipeline.settings import march_settings

    ckpt, cap, model, settings, ck = load_or_train(args)
    sets = build_sets(cap, settings, args.per_set, generated=("kick", "squat"))
    items = [
        it for name in ("training_poses", "novel_poses", "generated_novel_poses") for it in sets.get(name, [])
    ]
    base = march_settings(settings)
    print(
        f"checkpoint {ckpt} (step {ck['step']}), {len(items)} images of "
        f"{items[0][2].width}×{items[0][2].height}; reference {REFERENCE}",
        flush=True,
    )

    render_view(model, *items[0][:3], base)  # warm-up (lazy init, caches): not timed
    ref = measure(model, items, REFERENCE, base)
    rows = [{"label": "reference 64+32 ε=0", **ref}]
    print(f"  reference: {ref['seconds']:.2f} s/frame", flush=True)
    presets = [(n, {k: v for k, v in p.items() if k in RENDER_KNOBS}) for n, p in PRESETS.items()]
    configs = (
        [("default", {})]
        + SWEEP
        + [(f"preset {n}", p) for n, p in presets]
        + [("default, guide=shell", {"guide": "shell"})]
        + [(f"preset {n}, guide=shell", {**p, "guide": "shell"}) for n, p in presets]
    )
    for label, knobs in configs:
        r = measure(model, items, knobs, base, references=ref["images"])
        rows.append({"label": label, "knobs": knobs, **r})
        print(f"  {label}: {r['seconds']:.2f} s, {r['psnr_gt']:.2f} dB", flush=True)

    front = pareto(rows)
    default = next(r for r in rows if r["label"] == "default")
    lines = [
        f"# Speed-accuracy trade: {ckpt} (step {ck['step']}), {len(items)} images",
        "",
        "Seconds: median per frame incl. pose setup and shell build; PSNR/SSIM in the "
        "mask bounding box; 'vs ref' against the 64+32, ε = 0 render of the same model.",
        "",
        "| setting | s/frame | × default time | field evals/frame | × default evals | "
        "PSNR vs truth | SSIM vs truth | PSNR vs ref | Pareto |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        pr = "—" if r.get("psnr_ref") is None else f"{r['psnr_ref']:.2f}"
        lines.append(
            f"| {r['label']} | {r['seconds']:.3f} | {r['seconds'] / default['seconds']:.2f}"
            f" | {r['evals']:.0f} | {r['evals'] / default['evals']:.2f} | "
            f"{r['psnr_gt']:.2f} | {r['ssim_gt']:.4f} | {pr} | "
            f"{'★' if r['label'] in front else ''} |"
        )
    lines += ["", "## Cost vs image size (default settings, one training pose)", ""]
    lines += size_growth(model, items[0], base)
    lines += ["", "## Cost vs training frames and vocabulary size", ""]
    lines += data_growth(cap, model)
    md = "\n".join(lines) + "\n"
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(out / "tradeoff.md", lambda t: Path(t).write_text(md))
    blob = [{k: v for k, v in r.items() if k != "images"} for r in rows]
    atomic_write_bytes(out / "tradeoff.json", lambda t: Path(t).write_text(json.dumps(blob, indent=1)))
    plot(rows, front, out / "pareto.png", f"{ckpt} (step {ck['step']}), {len(items)} images")
    print(md)
    print(f"wrote {out / 'tradeoff.md'}, {out / 'pareto.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
