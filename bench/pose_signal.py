"""How much of a synthetic capture's novel-pose images is pose-dependent appearance, the
part a texture vocabulary can explain: each held-out image re-rendered (same geometry,
same camera) with the clothing's folds of other poses, against the true image.

    .venv/bin/python bench/pose_signal.py CAPTURE [--views 1 5]

Columns (PSNR in the mask's bounding box, dB, mean ± sem over novel frames x views):
folds of the rest pose (no folds: the whole pose-dependent signal), folds of the nearest
training frame by whole-body distance (the best a global key can give), folds of a pose
assembled part by part from each part's nearest training pose (the best body-part keys
can give; equal to the true pose when every part was seen). A model whose error is far
larger than the first column cannot show a difference between vocabularies at all. On a
capture with fold regions (``texvocab synth`` stores them) a second row scores the same
images on those pixels alone (PSNR, dB; texvocab.metrics.fold_region), over the images
that have one.
"""

from __future__ import annotations

import argparse

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("capture")
    ap.add_argument("--views", type=int, nargs="+", default=[1, 5])
    args = ap.parse_args(argv)

    from texvocab.body.parts import BODY_PARTS
    from texvocab.capture import open as open_capture
    from texvocab.capture.compositional import pairwise_part_distance
    from texvocab.capture.fold_regions import FoldRegions
    from texvocab.capture.synth import ground_truth_renderer
    from texvocab.metrics import metrics_in_bbox
    from texvocab.metrics.fold_region import fold_region_metrics

    cap = open_capture(args.capture)
    renderer, cams = ground_truth_renderer(cap)
    train = cap.poses[: cap.num_train]
    novel = list(cap.novel_frames)
    whole = sum(pairwise_part_distance(cap.poses[novel], train, j) for j in BODY_PARTS.values())
    nearest_whole = whole.argmin(1)
    rows = {"rest-pose folds": [], "nearest training frame's folds": [], "part-wise nearest folds": []}
    folds = FoldRegions.load(args.capture)
    on_folds = {name: [] for name in rows}
    for i, t in enumerate(novel):
        assembled = np.zeros_like(cap.poses[t])
        for joints in BODY_PARTS.values():
            k = pairwise_part_distance(cap.poses[t][None], train, joints)[0].argmin()
            assembled[list(joints)] = train[k][list(joints)]
        fold_poses = {
            "rest-pose folds": np.zeros_like(cap.poses[t]),
            "nearest training frame's folds": train[nearest_whole[i]],
            "part-wise nearest folds": assembled,
        }
        truth = renderer.render(cap.poses[t], cap.trans[t], [cams[v] for v in args.views])
        for name, fp in fold_poses.items():
            other = renderer.render(
                cap.poses[t], cap.trans[t], [cams[v] for v in args.views], texture_pose=fp
            )
            for v, (gt, mask), (img, _) in zip(args.views, truth, other, strict=True):
                rows[name].append(metrics_in_bbox(img, gt, mask)["psnr"])
                region = None if folds is None else folds.region(t, v)
                m = None if region is None else fold_region_metrics(img, gt, region)
                if m is not None:
                    on_folds[name].append(m["psnr_fold"])
    renderer.close()
    n = len(rows["rest-pose folds"])
    print(
        f"# pose-dependent appearance of {args.capture}: {len(novel)} novel frames x views "
        f"{args.views} = {n} images (PSNR bbox vs truth, mean ± sem)\n"
    )
    print("| pixels | " + " | ".join(rows) + " |\n" + "|---" * (len(rows) + 1) + "|")

    def cell(v) -> str:
        return f"{np.mean(v):.2f} ± {np.std(v, ddof=1) / np.sqrt(len(v)):.2f}" if len(v) > 1 else "n/a"

    print("| bbox | " + " | ".join(cell(v) for v in rows.values()) + " |")
    n_fold = len(on_folds["rest-pose folds"])
    if n_fold:
        print(f"| fold regions ({n_fold} images) | " + " | ".join(cell(v) for v in on_folds.values()) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
