"""The baseline side of ``bench/render_against.py``: renders frames with another checkout's
code, on request, so that two versions of texvocab are timed in one run.

    PYTHONPATH=TREE python bench/render_against_worker.py TREE CKPT FRAMES SIZE OUT

Runs with TREE's ``texvocab`` and TREE's ``bench/render_speed.py`` (its ``load``,
``items_of`` and ``timed_render``), so the frames, the timing and the render path are
that version's own: its default guided path is the surface-guided marcher at its ``fast``
preset (``guide=raster``). After loading it renders every frame once (the compiled kernels
load or compile, and each image is saved as ``OUT/baseline_<i>.npy``) and prints one line
``ready <JSON list of the frames' labels>``. Then for each line ``i`` read from stdin it
renders frame ``i`` again and prints ``<seconds> <field evaluations>``. An empty line or
the end of stdin ends it.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # before torch loads OpenMP


def main(argv: list[str]) -> int:
    tree, ckpt, frames, size, out = Path(argv[0]), argv[1], int(argv[2]), int(argv[3]), Path(argv[4])
    sys.path[:0] = [str(tree / "bench"), str(tree)]
    import numpy as np
    import render_speed as rs  # TREE's
    import torch

    from texvocab.pipeline.settings import PRESETS, march_settings

    torch.set_num_threads(2)

    class Args:
        checkpoint, capture = ckpt, None

    model, settings, cap, _ = rs.load(Args())
    items = rs.items_of(cap, settings, frames)
    if size:
        items = [(lb, p, t, cam.scaled(size / cam.width), gt, m) for lb, p, t, cam, gt, m in items]
    knobs = [f"{k}={v}" for k, v in PRESETS["fast"].items() if k != "image_scale"]
    march = march_settings(settings.with_overrides(knobs + ["guide=raster"]))
    for i, item in enumerate(items):
        img, _ = rs.timed_render(model, item, march)
        np.save(out / f"baseline_{i}.npy", img)
    print("ready " + json.dumps([it[0] for it in items]), flush=True)
    for line in sys.stdin:
        if not line.strip():
            break
        _, row = rs.timed_render(model, items[int(line)], march)
        print(f"{row['total']:.6f} {int(row['evals'])}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
