"""Temporary names carry their writer's pid and host; a killed writer's are swept by the
next write into their folder (checkpoints, videos), and other names never are."""

import os
import subprocess

import numpy as np

from texvocab.io.checkpoint import save_checkpoint
from texvocab.io.images import save_png
from texvocab.io.temp_files import TEMP_NAME, host_tag, sweep_stale, temp_file
from texvocab.pipeline.clip import write_mp4


def _dead_pid() -> int:
    proc = subprocess.Popen(["true"])
    proc.wait()
    return proc.pid


def _stale(folder, name, suffix):
    path = folder / f".{name}.tmp-{_dead_pid()}-{host_tag()}-deadbeef{suffix}"
    path.write_bytes(b"half")
    return path


def test_temp_names_match_the_pattern_with_this_pid(tmp_path):
    tmp = temp_file(tmp_path / "checkpoint.pt")
    m = TEMP_NAME.match(tmp.name)
    assert m and int(m["pid"]) == os.getpid() and m["host"] == host_tag() and tmp.suffix == ".pt"
    assert sweep_stale(tmp_path, force=True) == [] and tmp.exists()  # this process's own


def test_the_checkpoint_writer_sweeps_a_killed_save(tmp_path):
    stale = _stale(tmp_path, "checkpoint.pt", ".pt")
    other = tmp_path / ".checkpoint.pt.mine"
    other.write_bytes(b"user's")
    save_checkpoint(tmp_path / "checkpoint.pt", {"step": 1})
    assert not stale.exists() and other.exists() and (tmp_path / "checkpoint.pt").is_file()


def test_the_video_writer_sweeps_a_killed_encode(tmp_path):
    frames = [save_png(tmp_path / "f" / f"frame_{i}.png", np.full((16, 16, 3), i * 0.3)) for i in range(2)]
    stale = _stale(tmp_path, "clip.mp4", ".mp4")
    write_mp4(frames, tmp_path / "clip.mp4", 10.0)
    assert not stale.exists() and (tmp_path / "clip.mp4").is_file()
    assert not [p for p in tmp_path.iterdir() if TEMP_NAME.match(p.name)]
