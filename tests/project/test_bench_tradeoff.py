"""bench/tradeoff.py on the smallest real avatar: every knob of the sweep and every preset
measured against the 64+32 reference, the tables and the Pareto plot written, and the
plot redrawn from the saved rows alone."""

import json
import sys
from pathlib import Path

import pytest
from tiny_runs import smallest_run

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))

import tradeoff  # noqa: E402

from texvocab.pipeline.settings import PRESETS  # noqa: E402

pytestmark = pytest.mark.slow  # about 30 configurations rendered


def test_the_sweep_measures_every_knob_and_draws_its_front(tmp_path, capsys, monkeypatch):
    # a knob of each kind from the sweep (image scale, marcher samples, shell, the guided
    # marcher's own), beside every preset: the whole sweep is 40 renders of each image
    kinds = ("image_scale=0.25", "coarse=6", "shell=0.02", "residual_rays=false")
    monkeypatch.setattr(tradeoff, "SWEEP", [c for c in tradeoff.SWEEP if c[0] in kinds])
    assert len(tradeoff.SWEEP) == len(kinds)
    ck = smallest_run(tmp_path / "avatar")
    out = tmp_path / "tradeoff"
    assert tradeoff.main([str(ck), "--out", str(out), "--per-set", "1"]) == 0
    rows = json.loads((out / "tradeoff.json").read_text())
    labels = [r["label"] for r in rows]
    assert labels[0].startswith("reference") and "default" in labels
    assert all(label in labels for label, _ in tradeoff.SWEEP)
    assert all(f"preset {n}" in labels for n in PRESETS)
    for r in rows:
        assert r["seconds"] > 0 and r["evals"] > 0 and 0 < r["psnr_gt"] < 100
    default = next(r for r in rows if r["label"] == "default")
    # fewer coarse samples on the rays the marcher still marches never cost more evals
    # than many more; a quarter-size image costs fewer evals than the full one
    quarter = next(r for r in rows if r["label"] == "image_scale=0.25")
    assert quarter["evals"] < default["evals"]
    md = (out / "tradeoff.md").read_text()
    assert "| default | " in md and "★" in md and "Cost vs image size" in md
    assert (out / "pareto.png").stat().st_size > 1000
    (out / "pareto.png").unlink()
    assert tradeoff.main(["--out", str(out), "--plot-only"]) == 0
    assert (out / "pareto.png").is_file()
