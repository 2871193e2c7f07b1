"""bench/render_against.py: today's default render path against another checkout's, each
with its own code in one run. Here the other checkout is this one, so the two must agree
to the bit and the bench must say so."""

import sys
from pathlib import Path

from tiny_runs import smallest_run

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))

import render_against  # noqa: E402


def test_against_the_same_tree_gives_the_same_images_and_evaluations(tmp_path, capsys):
    ckpt = smallest_run(tmp_path)
    assert render_against.main([str(ckpt), str(ROOT), "--frames", "1", "--repeats", "2"]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith("summary: new_s=")
    summary = dict(kv.split("=") for kv in last.removeprefix("summary: ").split())
    assert float(summary["new_s"]) > 0 and float(summary["baseline_s"]) > 0
    assert float(summary["speedup"]) > 0
    assert summary["new_evals"] == summary["baseline_evals"] != "0"
    assert float(summary["psnr_delta_db"]) == 0.0
    assert summary["frames"] == "1" and summary["baseline"] == render_against.tree_commit(ROOT)


def test_a_folder_that_is_no_checkout_is_refused_in_one_line(tmp_path, capsys):
    assert render_against.main([str(tmp_path / "ckpt.pt"), str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and str(tmp_path) in err[0]
