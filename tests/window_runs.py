"""Run the viewer window for real under Xvfb with a scripted driver (app/testing/scripts.py)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PYTHON = sys.executable
XVFB = shutil.which("xvfb-run")


def run_window(
    source,
    script: str,
    tmp_path: Path,
    *extra: str,
    timeout: float = 150,
    command: tuple[str, ...] = (PYTHON, "-m", "texvocab_viewer"),
    env=None,
    cwd: Path = ROOT,
    size: str = "1280x800",
    screen: str = "1280x1024",
):
    """(process, report dict, screenshot path) of ``command SOURCE --script SCRIPT`` in a
    ``size`` window on an Xvfb ``screen`` with a 48 px neural render (``extra``: more
    arguments)."""
    assert XVFB is not None, "xvfb-run is missing: apt-get install xvfb xauth (see scripts/)"
    report, shot = tmp_path / f"{script}.json", tmp_path / f"{script}.png"
    cmd = [
        XVFB,
        "-a",
        "-s",
        f"-screen 0 {screen}x24",
        *command,
        *([] if source is None else [str(source)]),
        "--size",
        size,
        "--script",
        script,
        "--report",
        str(report),
        "--screenshot",
        str(shot),
        "--neural-resolution",
        "48",
        *extra,
    ]
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env)
    assert report.is_file(), f"no report; rc {proc.returncode}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return proc, json.loads(report.read_text()), shot
