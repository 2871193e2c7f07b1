"""How much of a synthetic capture's novel-pose images is pose-dependent appearance, the
part a texture vocabulary can explain: each held-out image re-rendered (same geometry,
same camera) with the clothing's folds of other poses, against the true image.

    .venv/bin/python bench/pose_signal.py CAPTURE [--views 1 5] [--avatar RUN/eval/metrics.json]

Columns (PSNR in the mask's bounding box, dB, mean ± sem over novel frames x views):
folds of the rest pose (no folds: the whole pose-dependent signal), folds of the nearest
training frame by whole-body distance (the best a global key can give), folds of a pose
assembled part by part from each part's nearest training pose (the best body-part keys
can give; equal to the true pose when every part was seen). A model whose error is far
larger than the first column cannot show a difference between vocabularies at all. On a
capture with fold regions (``texvocab synth`` stores them) a second row scores the same
images on those pixels alone (PSNR, dB; texvocab.metrics.fold_region), over the images
that have one. With ``--avatar``, a trained avatar's ``texvocab eval`` report on the same
capture (its novel_poses set) is paired with each column image by image (same frame and
view): the avatar's PSNR minus the column's, mean ± sem and the share of images where the
avatar is ahead. The first column's difference is how far the avatar's whole error is
below the pose-dependent signal.
"""

from __future__ import annotations

import argparse

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("capture")
    ap.add_argument("--views", type=int, nargs="+", default=[1, 5])
    ap.add_argument("--avatar", help="a texvocab eval metrics.json of an avatar trained on CAPTURE")
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
    avatar = None if args.avatar is None else _avatar_images(args.avatar)
    missing = [(t, v) for t in novel for v in args.views if avatar is not None and (t, v) not in avatar]
    if missing:
        raise SystemExit(
            f"error: {args.avatar}: no novel_poses image for frame {missing[0][0]}, view {missing[0][1]}"
        )
    rows = {"rest-pose folds": [], "nearest training frame's folds": [], "part-wise nearest folds": []}
    folds = FoldRegions.load(args.capture)
    on_folds = {name: [] for name in rows}
    keys, fold_keys = [], []
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
                    if name == "rest-pose folds":
                        fold_keys.append((t, v))
        keys += [(t, v) for v in args.views]
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
    if avatar is not None:
        _print_paired(avatar, rows, keys, on_folds, fold_keys)
    return 0


def _avatar_images(path: str) -> dict:
    """(frame, view) -> the novel_poses image row of a texvocab eval metrics.json."""
    import json
    from pathlib import Path

    try:
        images = json.loads(Path(path).read_text())["images"]
    except (OSError, ValueError, KeyError) as e:
        raise SystemExit(f"error: {path}: expected a texvocab eval metrics.json ({e})") from None
    return {(r["frame"], r["view"]): r for r in images if r.get("set") == "novel_poses"}


def _print_paired(avatar: dict, rows: dict, keys: list, on_folds: dict, fold_keys: list) -> None:
    """Avatar minus each column, per image, on the bbox and on the fold pixels."""

    def cell(diff) -> str:
        d = np.asarray(diff)
        return f"{d.mean():+.2f} ± {d.std(ddof=1) / np.sqrt(len(d)):.2f} ({(d > 0).mean():.0%})"

    head = "| avatar − column, paired (ahead) | " + " | ".join(rows) + " |"
    print("\n" + head + "\n" + "|---" * (len(rows) + 1) + "|")
    ours = [avatar[k]["psnr_bbox"] for k in keys]
    cells = " | ".join(cell(np.subtract(ours, v)) for v in rows.values())
    print(f"| bbox ({len(keys)} images) | {cells} |")
    fold = [avatar[k].get("psnr_fold") for k in fold_keys]
    if fold_keys and None not in fold:
        print(
            f"| fold regions ({len(fold_keys)} images) | "
            + " | ".join(cell(np.subtract(fold, v)) for v in on_folds.values())
            + " |"
        )


if __name__ == "__main__":
    raise SystemExit(main())
