"""Neural render speed: where the time of one frame of the avatar goes, and its accuracy.

Renders the avatar (a trained checkpoint, or without CKPT the real model architecture
untrained: its body-SDF geometric initialisation already puts the surface on the body)
for several poses and held-out views, and prints one Markdown table: per frame the time
split — pose context (posed body, surface index, vocabulary query, feature maps), shell
build (the shell marcher's; the surface-guided marcher builds what it needs of the shell
inside its render, counted under marching), field evaluations (seconds and count),
marching (ray bounds, in-shell paths, sample placement, compositing: the rest of the
marcher) — the wall seconds per frame, the process CPU seconds (the machine may be
shared; CPU time is the steadier number) and the PSNR against the capture's ground truth
(inside the mask's bounding box and full frame, texvocab.metrics). Each marcher variant
gets its rows and a mean row; the reference uniform marcher (64 + 64 samples per ray in
the body's bounding box, no shell) is timed on the first frames in the same run, on the
same field, for the ratio.

    .venv/bin/python bench/render_speed.py [CKPT] [--capture DIR] [--frames 3]
        [--variant "12+4:coarse_samples=12,fine_samples=4"] [--reference 1]
    .venv/bin/python bench/render_speed.py CKPT --compare [--frames 3] [--save DIR]
        [--variant "step3:residual_step=3"]

``--compare`` renders the same frames five ways in one run — ``new``: the default render
path as it is now (the surface-guided marcher, guide=raster, at the ``fast`` preset's
knobs, with the field's MLPs in ``--new-precision`` (by default ``auto``: bfloat16 where the
CPU has bf16 units, float32 where torch would emulate them), activations free
of subnormal numbers, ``NormalSoftplus``, and ``surface_reuse``: the field's projection
takes the closest faces the raster and the residual rays' mesh queries found);
``previous``: the default path as it was before any of that, switched back inside
today's code (``bench/render_against.py`` times an older checkout's own code instead)
(float32 MLPs with torch's nn.Softplus, and ``BEFORE``:
``surface_reuse=false``, every point searched; ``residual_groups=1``, the residual rays'
quadrature in one padded array; ``fallback_segment=8``; and the closest-face search's
kernel as it was, ``nearest_faces_plain``, and the residual rays' mesh samples in padded torch
arrays, :func:`plain_search`); the other paths run with
torch's nn.Softplus and float32 too — ``shell``: the shell marcher (guide=shell) at the
``fast`` preset; ``quality``: the shell marcher at the ``quality`` preset; ``reference``:
the uniform 64+32 marcher in the body's box — and prints per path seconds, field
evaluations, PSNR against the truth and against the reference, and as its last line
``summary: new_s=… previous_s=… reference_s=… new_evals=… previous_evals=…
reference_evals=… speedup=… psnr_delta_vs_quality_db=… psnr_delta_db=…`` (per-frame means;
speedup = previous_s / new_s; psnr_delta_db = the new path's PSNR against the truth minus
the previous path's). ``--size N`` renders at N×N (the capture's cameras scaled).

CKPT's capture is the one recorded in the checkpoint unless --capture is given. Without
CKPT and --capture a small synthetic capture (6 frames, 4 views, 256²) is made in a
temporary folder. Uses 2 threads (the machine's 2 cores) with OMP_WAIT_POLICY=PASSIVE
unless set otherwise: when another process holds a core, OpenMP threads that spin while
waiting made a frame ~10x slower (measured 22-28 s instead of 2.7 s per frame).
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # before torch loads OpenMP

import numpy as np  # noqa: E402
import torch  # noqa: E402
from render_timing import BEFORE, plain_search, plain_softplus, reference_render, timed_render  # noqa: E402

from texvocab.blas import budget_blas_threads  # noqa: E402


def parse_variant(text: str):
    """'name:key=value,key=value' -> (name, {key: value}) for MarchSettings fields."""
    from texvocab.render.settings import FLAT_NAMES

    name, _, body = text.partition(":")
    known = FLAT_NAMES
    kw = {}
    for item in filter(None, body.split(",")):
        key, eq, value = item.partition("=")
        if not eq or key not in known:
            raise SystemExit(
                f"error: --variant {text!r}: expected name:key=value,... with keys "
                f"from MarchSettings ({', '.join(known)})"
            )
        kw[key] = _value(value)
    return name, kw


def _value(text: str):
    """A --variant value: None, an int, a float, true/false, else the text (e.g. guide=raster)."""
    if text == "None":
        return None
    if text in ("true", "false"):
        return text == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def small_capture(root: Path) -> Path:
    """A 6-frame, 4-view 256² synthetic capture (4 training frames) under root."""
    from texvocab.body import default_body
    from texvocab.capture.motion import make_sequence
    from texvocab.capture.synth import SynthSettings, synthesize

    poses, trans = make_sequence([("walk", 4), ("arm_raise", 2)], seed=3)
    return synthesize(
        root / "capture",
        poses,
        trans,
        4,
        default_body(),
        SynthSettings(ring_views=4, raised_views=0, size=256, texture_size=512),
        progress=False,
    )


def load(args):
    """(model, settings, capture) from CKPT or an untrained model on a capture."""
    from texvocab.capture import open as open_capture
    from texvocab.pipeline.model import build_model, load_textures
    from texvocab.pipeline.settings import DataSettings, Settings

    if args.checkpoint:
        from texvocab.pipeline import load_avatar

        cap = open_capture(args.capture) if args.capture else None
        av = load_avatar(args.checkpoint, cap, progress=False)
        return av.model, av.settings, av.capture, f"checkpoint {args.checkpoint}"
    root = Path(args.capture) if args.capture else small_capture(Path(tempfile.mkdtemp()))
    cap = open_capture(root)
    settings = Settings(data=DataSettings(eval_views=tuple(v for v in (0, 1) if v < cap.num_views)))
    textures = load_textures(cap, settings, progress=False)
    with torch.random.fork_rng():  # seeded weights: PSNR comparable between runs
        torch.manual_seed(0)
        model = build_model(cap, settings, textures)
    model.eval()
    return model, settings, cap, f"untrained model (geometric init) on {root}"


def items_of(cap, settings, frames: int):
    """[(label, pose, trans, camera, gt (H, W, 3), mask (H, W))]: held-out views of novel
    (else training) frames, plus generated preset poses on a synthetic capture."""
    # a single-camera capture holds out frames, not views: its frames are seen from view 0
    views = [v for v in settings.data.eval_views if v < cap.num_views][:2] or [0]
    pool = list(cap.novel_frames) or list(cap.train_frames)
    picks = sorted({pool[int(i)] for i in np.linspace(0, len(pool) - 1, max(frames - 1, 1))})
    items = [
        (f"frame {t} view {v}", cap.poses[t], cap.trans[t], cap.cameras[v], cap.image(v, t), cap.mask(v, t))
        for t in picks
        for v in views[:1]
    ]
    if cap.synthetic:
        from texvocab.body.poses import preset
        from texvocab.capture.synth import ground_truth_renderer

        renderer, cams = ground_truth_renderer(cap)
        pose, trans = preset("squat")
        for v in views:
            rgb, mask = renderer.render(pose, trans, [cams[v]])[0]
            items.append((f"squat view {v}", pose, trans, cams[v], rgb, mask))
        renderer.close()
    return items[: max(frames, 1)]


def resized(items, size: int | None):
    """The items at size x size: cameras scaled, the truth and the mask resampled
    (bilinear, nearest), so paths compare at that resolution."""
    if not size:
        return items
    import torch.nn.functional as F

    out = []
    for label, pose, trans, cam, gt, mask in items:
        factor = size / cam.width
        img = torch.as_tensor(np.asarray(gt, dtype=np.float32)).permute(2, 0, 1)[None]
        img = F.interpolate(img, size=(size, size), mode="bilinear", align_corners=False)[0].permute(1, 2, 0)
        m = torch.as_tensor(np.asarray(mask, dtype=np.float32))[None, None]
        m = F.interpolate(m, size=(size, size), mode="nearest")[0, 0] > 0.5
        out.append((label, pose, trans, cam.scaled(factor), img.numpy(), m.numpy()))
    return out


def compare(
    model,
    settings,
    items,
    what: str,
    repeats: int = 1,
    save: Path | None = None,
    precision: str = "auto",
    variants: list[tuple[str, dict]] = (),
) -> int:
    """The five-way comparison of ``--compare``, plus ``variants`` ((name, MarchSettings
    knobs) of ``--variant``: the new path with those knobs, rendered in turn with the
    others); prints a table and the summary line. With
    ``save``, each path's images go there as ``<path>_<frame>.npy`` (float32 (H, W, 3)) and
    the field evaluations per path and frame as ``evals.json``, so two runs (e.g. before and
    after a change to the marchers) can be compared exactly."""
    from texvocab.metrics import evaluate_pair, psnr
    from texvocab.metrics.image import crop_to_bbox, mask_bbox
    from texvocab.pipeline.settings import PRESETS, march_settings

    def march(preset: str, guide: str, *extra: str):
        knobs = [f"{k}={v}" for k, v in PRESETS[preset].items() if k != "image_scale"]
        return march_settings(settings.with_overrides(knobs + [f"guide={guide}", *extra]))

    paths = {
        "new": march("fast", "raster", f"precision={precision}"),
        "previous": march("fast", "raster", "precision=float32").replace(**BEFORE),
        "shell": march("fast", "shell", "precision=float32"),
        "quality": march("quality", "shell", "precision=float32"),
    }
    newlike = {"new"}
    for name, kw in variants:
        if name in paths or name == "reference":
            raise SystemExit(f"error: --variant {name!r}: that name is one of the compared paths")
        paths[name] = paths["new"].replace(**kw)
        newlike.add(name)
    print(
        f"# render paths compared: {what}\n\n{len(items)} frames at {items[0][3].width}x"
        f"{items[0][3].height}, {torch.get_num_threads()} threads; seconds: best of "
        f"{max(repeats, 1)} per frame (the paths in turn), incl. pose context and shell; PSNR "
        "in the mask's bounding box.\n"
    )
    print("| path | frame | seconds | field evals | PSNR vs truth | PSNR vs reference |")
    print("|---|---|---|---|---|---|")
    rows = {name: [] for name in (*paths, "reference")}
    for i, item in enumerate(items):
        box = mask_bbox(item[5])
        ref_img, ref_row = reference_render(model, item, 64, 32)
        results = {"reference": (ref_img, ref_row)}
        # the repeats take the paths in turn, so that each path's best sees the same load
        # on a shared machine (the paths one after the other drifted by 10-20 %)
        for _ in range(max(repeats, 1)):
            for name, march in paths.items():
                with plain_softplus(model, name not in newlike), plain_search(name == "previous"):
                    img, row = timed_render(model, item, march)
                if name not in results or row["total"] < results[name][1]["total"]:
                    results[name] = (img, row)
        for name, (img, row) in results.items():
            p_gt = evaluate_pair(img, item[4], item[5])["psnr_bbox"]
            p_ref = psnr(crop_to_bbox(img, box), crop_to_bbox(ref_img, box))
            rows[name].append((row["total"], row["evals"], p_gt, p_ref))
            if save is not None:
                np.save(save / f"{name}_{i}.npy", img)
            print(
                f"| {name} | {item[0]} | {row['total']:.3f} | {int(row['evals']):,} | "
                f"{p_gt:.3f} | {min(p_ref, 99.0):.2f} |",
                flush=True,
            )
    if save is not None:
        (save / "evals.json").write_text(
            json.dumps({n: [int(r[1]) for r in rs] for n, rs in rows.items()}, indent=1) + "\n"
        )
    mean = {n: np.mean(np.array(r, dtype=np.float64), 0) for n, r in rows.items()}
    print()
    for n, (sec, ev, p_gt, p_ref) in mean.items():
        print(
            f"- {n}: {sec:.3f} s/frame, {ev:,.0f} field evaluations, PSNR {p_gt:.3f} dB vs "
            f"truth, {min(p_ref, 99.0):.2f} dB vs reference"
        )
    speedup = mean["previous"][0] / mean["new"][0]
    print(
        f"- previous / new: {speedup:.2f}x time; shell / new: "
        f"{mean['shell'][0] / mean['new'][0]:.2f}x; reference / new: "
        f"{mean['reference'][1] / mean['new'][1]:.1f}x field evaluations"
    )
    print(
        f"summary: new_s={mean['new'][0]:.3f} previous_s={mean['previous'][0]:.3f} "
        f"reference_s={mean['reference'][0]:.3f} new_evals={mean['new'][1]:.0f} "
        f"previous_evals={mean['previous'][1]:.0f} reference_evals={mean['reference'][1]:.0f} "
        f"speedup={speedup:.2f} psnr_delta_vs_quality_db={mean['new'][2] - mean['quality'][2]:+.3f} "
        f"psnr_delta_db={mean['new'][2] - mean['previous'][2]:+.3f}"
    )
    return 0


COLS = ("context", "shell", "field", "evals", "march", "total", "cpu", "psnr_bbox", "psnr_full")


def fmt(row: dict) -> str:
    cells = []
    for c in COLS:
        v = row.get(c)
        if v is None or (isinstance(v, float) and np.isnan(v)):
            cells.append("–")
        elif c == "evals":
            cells.append(f"{int(v):,}")
        elif c.startswith("psnr"):
            cells.append(f"{v:.3f}")
        else:
            cells.append(f"{v:.3f}")
    return " | ".join(cells)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("checkpoint", nargs="?", default=None, help="trained checkpoint (optional)")
    ap.add_argument(
        "--capture",
        default=None,
        help="capture folder (default: the checkpoint's, "
        "or a small synthetic one made in a temporary folder)",
    )
    ap.add_argument("--frames", type=int, default=3, help="frames (pose, view) to render")
    ap.add_argument(
        "--variant",
        action="append",
        default=[],
        metavar="NAME:KEY=VALUE,...",
        help="extra marcher variant on top of the checkpoint's settings; with --compare, on top of "
        "the new path, rendered in turn with the compared paths",
    )
    ap.add_argument(
        "--reference", type=int, default=1, help="frames also rendered by the uniform 64+64 reference marcher"
    )
    ap.add_argument("--repeats", type=int, default=1, help="renders per frame (best kept)")
    ap.add_argument("--size", type=int, default=None, help="render at N x N (the cameras scaled)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument(
        "--compare",
        action="store_true",
        help="new (guided, fast knobs, --new-precision) vs previous (the default path before the "
        "speed work: float32, nn.Softplus, no surface reuse) vs "
        "shell (fast) vs quality vs the uniform 64+32 reference; ends with a summary line",
    )
    ap.add_argument(
        "--new-precision",
        default="auto",
        choices=("float32", "bfloat16", "auto"),
        help="with --compare: the new path's render.precision (default auto: bfloat16 on a "
        "CPU with bf16 units, else float32)",
    )
    ap.add_argument(
        "--save",
        type=Path,
        default=None,
        metavar="DIR",
        help="with --compare: write each path's images (.npy) and field evaluations (evals.json) to DIR",
    )
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    budget_blas_threads(1)  # as the texvocab command does (texvocab/blas.py)
    if args.compare:
        model, settings, cap, what = load(args)
        if args.save is not None:
            args.save.mkdir(parents=True, exist_ok=True)
        items = resized(items_of(cap, settings, args.frames), args.size)
        extra = [parse_variant(v) for v in args.variant]
        return compare(model, settings, items, what, args.repeats, args.save, args.new_precision, extra)

    from texvocab.metrics import evaluate_pair
    from texvocab.pipeline.settings import march_settings

    model, settings, cap, what = load(args)
    base = march_settings(settings)
    variants = [("settings", {})] + [parse_variant(v) for v in args.variant]
    items = resized(items_of(cap, settings, args.frames), args.size)
    print(
        f"# render speed: {what}\n\n{len(items)} frames at {items[0][3].width}x"
        f"{items[0][3].height}, {torch.get_num_threads()} threads, OMP_WAIT_POLICY="
        f"{os.environ.get('OMP_WAIT_POLICY')}; seconds are wall time "
        "(cpu: process CPU seconds); march = marcher work other than field calls "
        "(bounds, paths, samples, compositing); PSNR against ground truth.\n"
    )
    print("| variant | frame | " + " | ".join(COLS) + " |")
    print("|---" * (len(COLS) + 2) + "|")
    means, rows_of = {}, {}
    for name, kw in variants:
        march = base.replace(**kw)
        rows = []
        for item in items:
            best = None
            for _ in range(max(args.repeats, 1)):
                img, row = timed_render(model, item, march)
                if best is None or row["total"] < best[1]["total"]:
                    best = (img, row)
            img, row = best
            m = evaluate_pair(img, item[4], item[5])
            row.update(psnr_bbox=m["psnr_bbox"], psnr_full=m["psnr_full"])
            rows.append(row)
            print(f"| {name} | {item[0]} | {fmt(row)} |", flush=True)
        means[name] = {c: float(np.mean([r[c] for r in rows])) for c in COLS}
        rows_of[name] = rows
        print(f"| **{name} mean** | | {fmt(means[name])} |", flush=True)
    ref = []
    for item in items[: args.reference]:
        img, row = reference_render(model, item, 64, 64)
        m = evaluate_pair(img, item[4], item[5])
        row.update(psnr_bbox=m["psnr_bbox"], psnr_full=m["psnr_full"])
        ref.append((item, row))
        print(f"| uniform 64+64 (reference) | {item[0]} | {fmt(row)} |", flush=True)
    print()
    for name in means:
        line = (
            f"- {name}: {means[name]['total']:.3f} s/frame (cpu {means[name]['cpu']:.3f} s), "
            f"{means[name]['evals']:,.0f} field evaluations, PSNR bbox "
            f"{means[name]['psnr_bbox']:.3f} dB"
        )
        if name != "settings":
            line += (
                f" ({means[name]['psnr_bbox'] - means['settings']['psnr_bbox']:+.3f} dB, "
                f"{means['settings']['total'] / means[name]['total']:.2f}x faster than "
                "settings)"
            )
        print(line)
    for item, row in ref:
        k = next(i for i, it in enumerate(items) if it is item)
        img, shell_row = timed_render(model, item, base)
        print(
            f"- reference uniform 64+64 on {item[0]}: {row['total']:.2f} s, {row['evals']:,} "
            f"evaluations; the shell marcher ({variants[0][0]}) is "
            f"{row['total'] / shell_row['total']:.1f}x faster with "
            f"{row['evals'] / shell_row['evals']:.1f}x fewer evaluations; PSNR bbox "
            f"{row['psnr_bbox']:.3f} (reference) vs {rows_of['settings'][k]['psnr_bbox']:.3f} dB"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
