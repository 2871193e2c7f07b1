"""The timeline's "Export video" and "Screenshot" buttons, clicked in the real window
(GLFW under Xvfb, ImGui Test Engine): an MP4 of the loaded AMASS-layout sequence whose
frame count is read back, and a screenshot folder with the neural render and the 3D
view; both under exports/ of the working folder, never replacing a file."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image
from pose_file_cases import amass_file
from tiny_runs import smallest_run

from texvocab.pipeline.clip import read_video_info

pytestmark = pytest.mark.slow  # Xvfb windows

XVFB = shutil.which("xvfb-run")


def test_export_video_and_screenshot_buttons(tmp_path):
    ckpt = smallest_run(tmp_path / "run")
    amass_file(tmp_path / "walk.npz", frames=17, rate=120.0)  # 5 frames at 30 fps
    work = tmp_path / "work"
    (work / "exports").mkdir(parents=True)
    (work / "exports" / "walk.mp4").write_bytes(b"mine")  # must survive the export
    report = tmp_path / "export.json"
    assert XVFB is not None, "xvfb-run is missing: apt-get install xvfb xauth (see scripts/)"
    cmd = [
        XVFB,
        "-a",
        "-s",
        "-screen 0 1280x1024x24",
        sys.executable,
        "-m",
        "texvocab_viewer",
        str(ckpt),
        "--size",
        "1280x800",
        "--script",
        "export",
        "--report",
        str(report),
        "--neural-resolution",
        "48",
        "--poses",
        str(tmp_path / "walk.npz"),
    ]
    proc = subprocess.run(cmd, cwd=work, capture_output=True, text=True, timeout=300)
    assert report.is_file(), f"rc {proc.returncode}\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}"
    rep = json.loads(report.read_text())
    assert proc.returncode == 0 and rep["ok"], (rep.get("error"), proc.stderr[-2000:])
    # the timeline holds every frame of the file and plays at its rate; the video keeps
    # every 4th frame (at most 30 per second of video) at the same speed
    assert rep["sequence_frames"] == 17 and rep["fps"] == 120
    assert rep["follow"] is True  # the video was exported with per-frame follow cameras
    video = rep["video"]
    assert not video["error"] and video["frames"] == 5
    assert video["path"].endswith("exports/walk_2.mp4")  # walk.mp4 was taken
    assert (work / "exports" / "walk.mp4").read_bytes() == b"mine"
    frames, size, fps = read_video_info(work / "exports" / "walk_2.mp4")
    assert frames == 5 and fps == 30 and max(size) in (48, 48 + 1)
    shot = rep["screenshot"]
    assert not shot["error"] and shot["path"].endswith("exports/shot")
    neural = np.asarray(Image.open(work / "exports" / "shot" / "neural.png"))
    view = np.asarray(Image.open(work / "exports" / "shot" / "view3d.png"))
    assert neural.shape == view.shape and max(neural.shape[:2]) == 48
    assert neural.max() > 30 and view.std() > 5  # something drawn in both
