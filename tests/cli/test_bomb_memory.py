"""Inputs built to fill memory are refused in little of it: each runs in a fresh process
through the real command line (or the pose-file reader every ``--poses`` goes through),
which then reports its peak resident set (VmHWM). The 1 GB budget is the reliability page's;
the process's imports alone take about a third of it."""

from __future__ import annotations

import json
import subprocess
import sys
import zipfile

import numpy as np
import pytest

BUDGET_KB = 1_000_000  # 1 GB

PROBE = r"""
import json, sys
from texvocab.errors import TexvocabError
kind, args = sys.argv[1], sys.argv[2:]
if kind == "poses":
    from texvocab.body.pose_files import read_pose_sequence
    try:
        read_pose_sequence(args[0], fps=30.0)
        message = "read"
    except TexvocabError as e:
        message = str(e)
    code = 2 if message != "read" else 0
else:
    import contextlib, io
    from texvocab.cli.main import main
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        try:
            code = main(args)
        except SystemExit as e:  # an option's own check (argparse)
            code = e.code
    message = err.getvalue().strip()
peak = next(ln for ln in open("/proc/self/status") if ln.startswith("VmHWM:"))
print(json.dumps([code, message, int(peak.split()[1])]))
"""


def probe(kind: str, *args: str) -> tuple[int, str, int]:
    run = subprocess.run(
        [sys.executable, "-c", PROBE, kind, *map(str, args)], capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, run.stderr[-2000:]
    code, message, peak_kb = json.loads(run.stdout.strip().splitlines()[-1])
    return code, message, peak_kb


def _zip_of_zeros(path, nbytes: int) -> None:
    """An .npz whose 'poses' member is ``nbytes`` of float64 zeros (a small file: zeros
    deflate about 1000:1)."""
    rows = nbytes // (72 * 8)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as archive:
        with archive.open("poses.npy", "w", force_zip64=True) as fh:
            np.lib.format.write_array_header_1_0(
                fh, {"descr": "<f8", "fortran_order": False, "shape": (rows, 72)}
            )
            block = bytes(72 * 8 * 4096)
            for _ in range(rows // 4096):
                fh.write(block)


@pytest.mark.slow
def test_a_zip_bomb_pose_file_is_refused_in_little_memory(tmp_path):
    path = tmp_path / "bomb.npz"
    _zip_of_zeros(path, 1_200 * 2**20)  # 1.2 GiB of zeros
    assert path.stat().st_size < 2 * 2**20
    code, message, peak = probe("poses", path)
    assert code == 2 and "bomb.npz" in message and "GiB" in message, message
    assert peak < BUDGET_KB, f"peak RSS {peak / 1024:.0f} MB"


def test_a_pose_file_with_a_tiny_frame_rate_is_refused_in_little_memory(tmp_path):
    """A 4 KB file stating 1e-4 fps: resampled to 30 fps it would ask for 300000 frames
    per stored frame."""
    path = tmp_path / "slow.npz"
    np.savez(path, poses=np.zeros((10, 72)), trans=np.zeros((10, 3)), mocap_framerate=np.float64(1e-4))
    assert path.stat().st_size < 8192
    code, message, peak = probe("poses", path)
    assert code == 2 and "slow.npz" in message, message
    assert peak < BUDGET_KB, f"peak RSS {peak / 1024:.0f} MB"


@pytest.mark.parametrize(
    ("argv", "names"),
    [
        (["synth", "{tmp}/cap", "--size", "100000"], "--size"),
        (
            ["render", "{tmp}/none.pt", "--poses", "{tmp}/none.npz", "--out", "{tmp}/v.mp4", "--fps", "1e9"],
            "fps",
        ),
    ],
)
def test_absurd_sizes_are_refused_before_any_allocation(tmp_path, argv, names):
    code, message, peak = probe("cli", *(a.format(tmp=tmp_path) for a in argv))
    assert code == 2 and message.startswith("error: ") and names in message, message
    assert len(message.splitlines()) == 1
    assert peak < BUDGET_KB, f"peak RSS {peak / 1024:.0f} MB"
