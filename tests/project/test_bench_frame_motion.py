"""bench/frame_motion.py: frame t against frame t - d, still, carried by the fitted body
and moved by the best local image motion, on the HumanNeRF-layout stand-in."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from humannerf_cases import make_truth, write_standin

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))

from frame_motion import block_matched  # noqa: E402


def test_block_matching_undoes_a_shift_and_never_loses_to_standing_still():
    rng = np.random.default_rng(0)
    target = rng.random((96, 96, 3)).astype(np.float32)
    source = np.roll(target, (3, -2), axis=(0, 1))  # the content moved by (3, -2) px
    sel = np.zeros((96, 96), bool)
    sel[16:80, 16:80] = True
    rebuilt = block_matched(target, source, sel, block=16, reach=4)
    np.testing.assert_array_equal(rebuilt[sel], target[sel])
    assert np.abs(source - target)[sel].mean() > 0.2
    # a change no shift explains: per block, the best shift is at least as good as none
    other = rng.random((96, 96, 3)).astype(np.float32)
    rebuilt = block_matched(target, other, sel, block=16, reach=2)
    assert ((rebuilt - target)[sel] ** 2).sum() <= ((other - target)[sel] ** 2).sum()
    assert (rebuilt[~sel] == target[~sel]).all()
    with_reach_0 = block_matched(target, other, sel, block=16, reach=0)
    np.testing.assert_array_equal(with_reach_0[sel], other[sel])


@pytest.mark.slow  # the bench end to end in a subprocess
def test_bench_prints_the_table_and_its_summary(tmp_path):
    from texvocab.body import default_body

    body = default_body()
    root = write_standin(tmp_path / "subject", body, make_truth(body))
    before = sorted(p.relative_to(root) for p in root.rglob("*") if "texvocab_cache" not in p.parts)
    cmd = [sys.executable, str(ROOT / "bench" / "frame_motion.py"), str(root), "--frames", "2"]
    cmd += ["--offsets", "1", "--block", "16", "--reach", "4", "--set", "data.texture_size=64"]
    run = subprocess.run(cmd + ["--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    last = run.stdout.strip().splitlines()[-1]
    assert last.startswith("summary: d=1 still=") and " matched=" in last and last.endswith("frames=2")
    table = json.loads((tmp_path / "out" / "frame_motion.json").read_text())["table"]["1"]["all"]
    assert len(table["still"]) == 2
    # the painted person's clothes stay put: its own map and the fitted body carry a frame
    # far better than no motion does, and the best shifts are never worse than none
    for k in range(2):
        assert table["block-matched"][k] >= table["still"][k]
        assert table["own map"][k] > table["still"][k]
    assert "| 1 | all | 2 |" in run.stdout
    after = sorted(p.relative_to(root) for p in root.rglob("*") if "texvocab_cache" not in p.parts)
    assert after == before
    bad = subprocess.run(cmd[:3] + ["--offsets", "99"], capture_output=True, text=True, timeout=120)
    assert bad.returncode != 0 and "error: --offsets 99" in bad.stderr
