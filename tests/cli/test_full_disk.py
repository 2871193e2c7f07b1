"""A full disk, for real (a small tmpfs): training stops with one line naming the step the
intact checkpoint holds, the previous checkpoint keeps its bytes and no temporary file is
left; synth and prepare answer with one line and leave no partial file."""

import hashlib
import shutil

import pytest
from small_disk import small_disk
from train_cases import set_arguments, tiny_settings

from texvocab.cli.main import main
from texvocab.io.checkpoint import load_checkpoint
from texvocab.method.texmap import load_texture_map


@pytest.fixture
def disk(tmp_path):
    with small_disk(tmp_path) as d:
        yield d


def _error_line(err: str) -> str:
    assert "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if ln.startswith("error: ")]
    assert len(lines) == 1, err
    return lines[0]


def _hidden(folder) -> list:
    return sorted(p.name for p in folder.rglob(".*"))


def _train(world, out, *extra) -> list[str]:
    sets = set_arguments(tiny_settings(iterations=2, perceptual="off"))
    return ["train", str(world / "cap"), "--out", str(out), *sets, *extra]


def test_train_on_a_full_disk_keeps_the_last_checkpoint(world, disk, capsys):
    run = disk.root / "run"
    run.mkdir()
    shutil.copy(world / "run" / "checkpoint.pt", run)
    before = hashlib.sha256((run / "checkpoint.pt").read_bytes()).hexdigest()
    disk.leave(free=(run / "checkpoint.pt").stat().st_size // 2)  # not a second one
    argv = _train(world, run, "--resume", "--iterations", "3", "--set", "train.checkpoint_every=1")
    assert main(argv) == 2
    line = _error_line(capsys.readouterr().err)
    assert line == (
        f"error: {run / 'checkpoint.pt'}: no space left on device; the last checkpoint (step 2) is intact"
    )
    assert hashlib.sha256((run / "checkpoint.pt").read_bytes()).hexdigest() == before
    assert load_checkpoint(run / "checkpoint.pt")["step"] == 2
    assert sorted(p.name for p in run.iterdir()) == ["checkpoint.pt"]  # no temp file, no lock


def test_train_with_no_room_for_a_checkpoint_says_none_was_written(world, disk, capsys):
    disk.leave(free=64 * 1024)
    run = disk.root / "run"
    assert main(_train(world, run, "--iterations", "1")) == 2
    line = _error_line(capsys.readouterr().err)
    assert line.endswith("checkpoint.pt: no space left on device; no checkpoint was written"), line
    assert list(run.iterdir()) == []


def test_synth_on_a_full_disk_leaves_nothing(disk, capsys):
    disk.leave(free=16 * 1024)
    out = disk.root / "cap"
    argv = ["synth", str(out), "--frames", "2", "--size", "32", "--ring-views", "3"]
    assert main(argv + ["--raised-views", "0", "--texture-size", "64"]) == 2
    line = _error_line(capsys.readouterr().err)
    kept = "nothing was written (the partial capture is removed)"
    assert line == f"error: {out}: no space left on device; {kept}"
    assert list(disk.root.iterdir()) == []


@pytest.mark.parametrize("free_pages", [0, 2])
def test_prepare_on_a_full_disk_keeps_whole_maps_only(world, disk, free_pages, capsys):
    cap = disk.root / "cap"
    shutil.copytree(world / "cap", cap, ignore=shutil.ignore_patterns("texvocab_cache"))
    (cap / "texvocab_cache").mkdir()
    disk.leave(free=free_pages * 4096)  # a map at 32² takes about one page
    assert main(["prepare", str(cap), "--texture-size", "32"]) == 2
    line = _error_line(capsys.readouterr().err)
    assert "no space left on device" in line and "of 4 texture maps are cached" in line, line
    maps = sorted((cap / "texvocab_cache").rglob("*.npz"))
    assert f"{len(maps)} of 4 texture maps" in line and (len(maps) > 0) == (free_pages > 0), line
    assert all(load_texture_map(p)[0].shape[0] == 32 for p in maps)  # whole files only
    assert _hidden(cap) == []


@pytest.mark.parametrize("command", ["eval", "render"])
def test_eval_and_render_on_a_full_disk_give_one_line(world, disk, tmp_path, command, capsys):
    import numpy as np

    ckpt, out = str(world / "run" / "checkpoint.pt"), disk.root / "out"
    if command == "eval":
        argv = ["eval", ckpt, str(world / "cap"), "--per-set", "1", "--out", str(out)]
    else:
        np.savez(tmp_path / "still.npz", poses=np.zeros((1, 72)))
        argv = ["render", ckpt, "--poses", str(tmp_path / "still.npz"), "--out", str(out)]
    (disk.root / "filler").write_bytes(b"x")  # a tmpfs of size 0 would be unlimited
    disk.leave(free=0)
    assert main(argv) == 2
    line = _error_line(capsys.readouterr().err)
    assert line.startswith(f"error: {out}") and f"no space left on device (texvocab {command})" in line
    assert _hidden(disk.root) == []  # no temporary file left
