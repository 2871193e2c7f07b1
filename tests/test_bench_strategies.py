"""bench/strategies.py's report: per-strategy means over seeds and paired part - other
differences computed from the same seeds and images."""
import argparse
import importlib.util
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def _load():
    spec = importlib.util.spec_from_file_location("bench_strategies", ROOT / "bench" / "strategies.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_report_pairs_seeds_and_images():
    bench = _load()
    psnr = {("part", 0): [30.0, 31.0], ("global", 0): [29.0, 29.5],
            ("part", 1): [28.0, 28.0], ("global", 1): [28.5, 28.5]}
    runs = [{"strategy": s, "seed": k, "per_image": {"psnr_bbox": v, "ssim_bbox": [0.5, 0.5],
                                                     "lpips": [None, None]}}
            for (s, k), v in psnr.items()]
    md = bench.report(runs, argparse.Namespace(iterations=7), Path("cap"))
    assert "| part | 29.2500 (2.5000) |" in md  # seed means 30.5 and 28.0
    # paired per seed: +1.25 (seed 0), -0.5 (seed 1); mean +0.375, range straddles 0
    assert "| global | +0.3750 [-0.5000, +1.2500]" in md and "+1.25, -0.50" in md
    d = np.array([1.0, 1.5, -0.5, -0.5])
    assert f"| global | {d.mean():+.3f} ± {d.std(ddof=1) / 2:.3f} (n = 4) | 50% |" in md
