"""How much a trained avatar uses its texture-vocabulary feature f(Θ, x) (Eqs. 5-9):
render the same held-out images with the feature as trained, with the feature zeroed,
and with every pose's keys replaced by those of one fixed training pose; report PSNR
and the paired difference to "as trained".

    .venv/bin/python bench/feature_share.py CKPT [CKPT ...] [--set novel_poses]
        [--per-set 10] [--preset fast] [--fixed-frame 0]

If zeroing the feature costs little, the field decodes appearance from its other inputs
(the pose Θ it also receives, the canonical position) and no choice of vocabulary can
change its novel-pose quality much; if fixed keys cost as much as zeroing, the feature
matters only through pose-specific key selection.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

VARIANTS = ("as trained", "feature zeroed", "keys of a fixed pose")


def render(model, item, march, variant: str, fixed) -> np.ndarray:
    """(H, W, 3) render of one evaluation item with the texture feature as ``variant``."""
    from texvocab.pipeline import ShellGeometry, render_image

    pose, trans, cam = item[0], item[1], item[2]
    with torch.no_grad():
        ctx = model.pose_feature.context(pose, trans)
        if variant == "feature zeroed":
            ctx.features = ctx.features.zeros_like()
        elif variant == "keys of a fixed pose":
            ctx.frames, ctx.part_coef, ctx.features = fixed.frames, fixed.part_coef, fixed.features
        shell = ShellGeometry.build(
            ctx.vertices,
            model.body.faces,
            march.shell_width,
            march.shell_voxel,
            march.shell_exact,
            index=ctx.index,
        )
        out = render_image(model.for_pose(ctx), cam, ctx.vertices, model.body.faces, march, shell=shell)
    return out.rgb.numpy()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("checkpoints", nargs="+")
    ap.add_argument("--set", default="novel_poses", choices=("novel_poses", "training_poses"))
    ap.add_argument("--per-set", type=int, default=10, help="frames (x every evaluation view)")
    ap.add_argument("--preset", choices=("fast", "balanced", "quality"), default="fast")
    ap.add_argument("--fixed-frame", type=int, default=0, help="training frame whose keys are used")
    args = ap.parse_args(argv)

    from texvocab.metrics import metrics_in_bbox
    from texvocab.pipeline import load_avatar, march_settings
    from texvocab.pipeline.evaluate import build_sets
    from texvocab.pipeline.settings import render_overrides

    print(
        "| checkpoint | strategy | images | "
        + " | ".join(f"PSNR {v}" for v in VARIANTS)
        + " | zeroed - trained | fixed - trained |"
    )
    print("|---" * (5 + len(VARIANTS)) + "|")
    for ckpt in args.checkpoints:
        av = load_avatar(ckpt, progress=False)
        settings = render_overrides(av.settings, args.preset, [])
        march = march_settings(settings)
        items = build_sets(av.capture, settings, args.per_set, generated=())[args.set]
        cap = av.capture
        fixed = av.model.pose_feature.context(cap.poses[args.fixed_frame], cap.trans[args.fixed_frame])
        psnr = {v: [] for v in VARIANTS}
        for item in items:
            gt, mask = item[3], item[4]
            for v in VARIANTS:
                psnr[v].append(metrics_in_bbox(render(av.model, item, march, v, fixed), gt, mask)["psnr"])
        base = np.array(psnr[VARIANTS[0]])
        cells = [f"{np.mean(psnr[v]):.2f}" for v in VARIANTS]
        diffs = []
        for v in VARIANTS[1:]:
            d = np.array(psnr[v]) - base
            diffs.append(f"{d.mean():+.2f} ± {d.std(ddof=1) / np.sqrt(len(d)):.2f}")
        print(
            f"| {Path(ckpt).parent.name}/{Path(ckpt).parent.parent.name} | {av.settings.vocab.strategy} | "
            f"{len(items)} | " + " | ".join(cells + diffs) + " |",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
