"""A capture on a read-only mount: every command runs on it, its texture maps go to the
user's cache folder ($XDG_CACHE_HOME/texvocab/captures/NAME-DIGEST/), said in one line,
and nothing is written into the capture. The mount stops root too (readonly_mount.py)."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from disk_snapshot import snapshot
from readonly_mount import read_only_copy, unmount_all

from texvocab.body import default_body
from texvocab.capture.motion import make_sequence
from texvocab.capture.synth import SynthSettings, synthesize
from texvocab.cli.main import main

TINY = [
    "--set", "texture_size=32", "--set", "num_keys=1", "--set", "k=1", "--set", "encoder=small",
    "--set", "rays_per_batch=64", "--set", "coarse_samples=8", "--set", "fine_samples=4",
    "--set", "field.hidden=16", "--set", "field.sdf_layers=1", "--set", "field.color_layers=1",
    "--set", "field.pos_freqs=2", "--set", "perceptual=off", "--set", "eval_views=1",
]  # fmt: skip


@pytest.fixture(scope="module")
def ro_capture(tmp_path_factory, request):
    """(read-only capture folder, base): 6 views of 32², 3 frames (2 training)."""
    base = tmp_path_factory.mktemp("ro_capture")
    poses, trans = make_sequence([("walk", 3)], seed=2)
    settings = SynthSettings(ring_views=6, raised_views=0, size=32, texture_size=64)
    synthesize(base / "src", poses, trans, 2, default_body(), settings, progress=False)
    request.addfinalizer(unmount_all)
    return read_only_copy(base / "src", base / "cap"), base


@pytest.fixture
def xdg(ro_capture, monkeypatch):
    cache = ro_capture[1] / "xdg"
    monkeypatch.setenv("XDG_CACHE_HOME", str(cache))
    return cache


def _maps(cache):
    return {p: p.stat().st_mtime_ns for p in sorted(cache.rglob("frame_*.npz"))}


def _run(argv, capsys):
    code = main(argv)
    out = capsys.readouterr()
    assert code == 0, out.out + out.err
    return out


def test_prepare_and_train_put_the_maps_in_the_user_cache(ro_capture, xdg, capsys, caplog):
    cap, base = ro_capture
    before = snapshot(cap)
    _run(["prepare", str(cap), "--texture-size", "32", "--eval-views", "1"], capsys)
    told = [r.getMessage() for r in caplog.records if "read-only" in r.getMessage()]
    assert len(told) == 1 and told[0].startswith(f"capture {cap} is read-only: texture maps go to {xdg}")
    maps = _maps(xdg / "texvocab" / "captures")
    assert len(maps) == 2 and all(p.parent.parent.name.startswith("cap-") for p in maps)
    assert not (cap / "texvocab_cache").exists() and snapshot(cap) == before

    _run(["train", str(cap), "--out", str(base / "run"), "--iterations", "1", *TINY], capsys)
    assert (base / "run" / "checkpoint.pt").is_file()
    assert _maps(xdg / "texvocab" / "captures") == maps  # found there, not rebuilt
    assert snapshot(cap) == before


def test_eval_render_and_shot_find_the_maps_there(ro_capture, xdg, capsys):
    cap, base = ro_capture
    if not (base / "run" / "checkpoint.pt").is_file():
        pytest.skip("needs the run of test_prepare_and_train_put_the_maps_in_the_user_cache")
    maps, before = _maps(xdg), snapshot(cap)
    ckpt = str(base / "run" / "checkpoint.pt")
    _run(["eval", ckpt, str(cap), "--per-set", "1", "--out", str(base / "eval")], capsys)
    assert (base / "eval" / "metrics.md").is_file()
    np.savez(base / "still.npz", poses=np.zeros((2, 72)))
    render = ["render", ckpt, "--poses", str(base / "still.npz"), "--out", str(base / "frames")]
    _run(render + ["--capture", str(cap)], capsys)
    assert len(list((base / "frames").glob("frame_*.png"))) == 2
    _run(["shot", ckpt, "--capture", str(cap), "--out", str(base / "shots")], capsys)
    from texvocab_viewer.state import load_viewer_data  # what `texvocab view` opens

    assert load_viewer_data(ckpt, capture=str(cap)).model is not None
    assert _maps(xdg) == maps and snapshot(cap) == before


def test_contact_sheet_of_a_read_only_capture_goes_to_the_working_folder(ro_capture, capsys, tmp_path):
    cap, _ = ro_capture
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        out = _run(["contact-sheet", str(cap), "--frames", "0"], capsys).out
    finally:
        os.chdir(cwd)
    assert f"capture {cap} is read-only: the contact sheet goes to" in out
    assert (tmp_path / "contact_sheet_cap.png").is_file() and not (cap / "contact_sheet.png").exists()


def test_a_cache_that_cannot_be_written_either_is_one_error_line(ro_capture, monkeypatch, capsys):
    cap, base = ro_capture
    monkeypatch.setenv("XDG_CACHE_HOME", str(cap / "nested"))  # inside the read-only mount
    assert main(["prepare", str(cap), "--texture-size", "16", "--eval-views", "1"]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("error:")]
    assert len(err) == 1 and "texture-map cache" in err[0] and "read-only file system" in err[0], err


def test_the_user_sees_one_line_on_stderr(ro_capture, tmp_path):
    """The real command line: the warning reaches stderr once, though every frame's map
    asks where the cache is."""
    cap, _ = ro_capture
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "xdg")}
    texvocab = str(Path(sys.executable).parent / "texvocab")
    argv = [texvocab, "prepare", str(cap), "--texture-size", "16", "--eval-views", "1"]
    proc = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    told = [ln for ln in proc.stderr.replace("\r", "\n").splitlines() if "read-only" in ln]
    assert len(told) == 1, proc.stderr
    assert told[0].startswith(f"capture {cap} is read-only: texture maps go to {tmp_path}/xdg/texvocab/")
