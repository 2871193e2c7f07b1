"""Texture maps laid on a frame's posed body against its image (texvocab.method.texture_transfer,
bench/texture_transfer.py) on the HumanNeRF-layout stand-in: a synthetic person with exact
fits, whose painted clothes look the same in every frame."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from humannerf_cases import make_truth, write_standin

from texvocab.body import default_body
from texvocab.capture import open as open_capture
from texvocab.method.texmap import TexmapSettings, load_texture_map, prepare_texture_maps
from texvocab.method.texture_transfer import body_view, interior_psnr, transfer_scores

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def standin(tmp_path_factory):
    body = default_body()
    root = write_standin(tmp_path_factory.mktemp("transfer") / "subject", body, make_truth(body))
    cap = open_capture(root)
    paths = prepare_texture_maps(cap, TexmapSettings(size=64, views=(0,)), progress=False)
    maps = [load_texture_map(p) for p in paths]
    return root, cap, np.stack([t for t, _ in maps]), np.stack([c for _, c in maps])


def test_own_map_predicts_its_frame_and_a_wrong_map_does_not(standin):
    _, cap, tex, cov = standin
    bv = body_view(cap, 2, 0, tex.shape[1])
    assert bv.interior.sum() > 200 and (bv.interior <= bv.hit).all()
    own = interior_psnr(bv, tex[2], cov[2] > 0)
    flipped = interior_psnr(bv, tex[2][::-1, ::-1].copy(), None)  # texels at the wrong UVs
    assert own["psnr"] > 22 and own["psnr"] > flipped["psnr"] + 6
    assert own["psnr_blurred"] > own["psnr"]  # the blur hides sub-texel detail only
    assert own["pixels"] <= bv.interior.sum()


def test_transfer_table_scores_offsets_blend_and_mean(standin):
    _, cap, tex, cov = standin
    mean = tex.mean(0)
    table = transfer_scores(cap, tex, cov, [2, 5], [cap.num_train], (1, 3), lambda pose: tex[0], mean)
    assert set(table) == {"own", "d=1", "d=3", "vocabulary blend", "mean texture"}
    assert table["own"]["frames"] == 2 and table["d=3"]["frames"] == 1  # frame 2 has no 3 before it
    assert table["vocabulary blend"]["frames"] == 1
    # the painted person: a texel looks alike in neighbouring frames, far above a random map
    assert table["d=1"]["psnr"] > 20
    rand = np.random.default_rng(0).random(tex[0].shape).astype(np.float32)
    noisy = transfer_scores(cap, tex, cov, [], [cap.num_train], (1,), lambda pose: rand, rand)
    assert noisy["vocabulary blend"]["psnr"] < table["d=1"]["psnr"] - 6


@pytest.mark.slow  # the bench end to end in a subprocess
def test_bench_prints_the_table_and_its_summary(standin, tmp_path):
    root = standin[0]
    before = sorted(p.relative_to(root) for p in root.rglob("*") if "texvocab_cache" not in p.parts)
    run = subprocess.run(
        [
            sys.executable,
            str(ROOT / "bench" / "texture_transfer.py"),
            str(root),
            "--frames",
            "3",
            "--offsets",
            "1",
            "2",
            "--set",
            "data.texture_size=64",
            "--set",
            "vocab.num_keys=4",
            "--set",
            "vocab.k=2",
            "--out",
            str(tmp_path / "out"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    last = run.stdout.strip().splitlines()[-1]
    assert last.startswith("summary: own=") and " blend=" in last and " mean=" in last
    table = json.loads((tmp_path / "out" / "texture_transfer.json").read_text())["table"]
    assert table["own"]["frames"] >= 1 and table["vocabulary blend"]["frames"] >= 1
    assert "| vocabulary blend |" in (tmp_path / "out" / "texture_transfer.md").read_text()
    after = sorted(p.relative_to(root) for p in root.rglob("*") if "texvocab_cache" not in p.parts)
    assert after == before  # nothing but the texture cache written into the capture
