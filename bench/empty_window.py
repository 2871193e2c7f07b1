"""The baseline row of bench/viewer_ui.py: frame times of an empty hello_imgui window of the
viewer's size and framebuffer at full speed under Xvfb, i.e. what GL under llvmpipe and
the X server cost per frame before the viewer draws anything.

    python bench/empty_window.py OUT.json WxH SECONDS   # what run_empty runs under xvfb-run
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path


def empty_window_child(size: str, seconds: float, out: str) -> None:
    """Frame times of an empty hello_imgui window (one text line), idling off: what this
    machine's GL and X server cost per frame before the viewer draws anything."""
    import time

    from imgui_bundle import hello_imgui, imgui, immapp

    wall, cpu, process, t0 = [], [], [], time.perf_counter()

    def gui():
        wall.append(time.perf_counter())
        cpu.append(time.thread_time())
        process.append(time.process_time())  # with Mesa's raster threads
        imgui.text("empty window")
        if wall[-1] - t0 > seconds + 1:
            hello_imgui.get_runner_params().app_shall_exit = True

    rp = hello_imgui.RunnerParams()
    rp.app_window_params.window_geometry.size = tuple(int(v) for v in size.split("x"))
    rp.callbacks.show_gui = gui
    rp.ini_disable = True
    rp.fps_idling.enable_idling = False
    from texvocab_viewer.window import WINDOW_MSAA_SAMPLES  # the viewer's framebuffer, not hello_imgui's 8x

    rp.renderer_backend_options.open_gl_options.anti_aliasing_samples = WINDOW_MSAA_SAMPLES
    immapp.run(rp)
    keep = [i for i, t in enumerate(wall) if t - t0 > 1][1:]  # skip the first second
    Path(out).write_text(
        json.dumps(
            {
                "wall": [(wall[i] - wall[i - 1]) * 1000 for i in keep],
                "cpu": [(cpu[i] - cpu[i - 1]) * 1000 for i in keep],
                "process_cpu": [(process[i] - process[i - 1]) * 1000 for i in keep],
            }
        )
    )


def run_empty(size: str, seconds: float) -> dict:
    """:func:`empty_window_child` under xvfb-run: its frame times (ms) as a dict."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "empty.json"
        subprocess.run(
            [
                shutil.which("xvfb-run"),
                "-a",
                "-s",
                "-screen 0 1920x1200x24",
                sys.executable,
                __file__,
                out.as_posix(),
                size,
                str(seconds),
            ],
            check=True,
            capture_output=True,
        )
        return json.loads(out.read_text())


if __name__ == "__main__":
    empty_window_child(sys.argv[2], float(sys.argv[3]), sys.argv[1])
