"""UI responsiveness of the viewer window: frame times at 1280x800 (under Xvfb, Mesa
llvmpipe) while idle and while the progressive neural render runs in its worker thread.

Runs ``python -m app.window CHECKPOINT --script bench:SECONDS:RES`` under xvfb-run (the
per-frame driver in app/drivers.py: idling off, idle phase, then a phase in which
the left shoulder moves a little whenever a render finishes, so one is always running;
only frames while the worker is busy count there), then a phase in which the shoulder
moves every frame as under a dragged slider. Prints a Markdown table of the wall
time between frames (median, p95, max) and the UI thread's own CPU time per frame, with
the ratio to idle; a first row measures an empty hello_imgui window of the same size (what
GL under llvmpipe and the X server cost before the viewer draws anything); then the
neural levels' timings.

    .venv/bin/python bench/viewer_ui.py /tmp/run_part/checkpoint.pt [--seconds 10] [--res 256]
"""
from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def run(checkpoint: str, seconds: float, res: int, size: str, threads: int | None,
        nice: int | None = None) -> dict:
    xvfb = shutil.which("xvfb-run")
    if xvfb is None:
        sys.exit("error: xvfb-run is missing (apt-get install xvfb xauth)")
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "bench.json"
        cmd = [xvfb, "-a", "-s", "-screen 0 1920x1200x24", sys.executable, "-m", "app.window",
               checkpoint, "--size", size, "--script", f"bench:{seconds}:{res}",
               "--report", str(report)]
        if threads:
            cmd += ["--neural-threads", str(threads)]
        if nice is not None:
            cmd += ["--neural-nice", str(nice)]
        proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
        if not report.is_file():
            sys.exit(f"error: the window wrote no report (rc {proc.returncode}):\n{proc.stderr[-3000:]}")
        return json.loads(report.read_text())


def empty_window_child(size: str, seconds: float, out: str) -> None:
    """Frame times of an empty hello_imgui window (one text line), idling off: what this
    machine's GL and X server cost per frame before the viewer draws anything."""
    import time

    from imgui_bundle import hello_imgui, imgui, immapp

    wall, cpu, t0 = [], [], time.perf_counter()

    def gui():
        wall.append(time.perf_counter())
        cpu.append(time.thread_time())
        imgui.text("empty window")
        if wall[-1] - t0 > seconds + 1:
            hello_imgui.get_runner_params().app_shall_exit = True

    rp = hello_imgui.RunnerParams()
    rp.app_window_params.window_geometry.size = tuple(int(v) for v in size.split("x"))
    rp.callbacks.show_gui = gui
    rp.ini_disable = True
    rp.fps_idling.enable_idling = False
    immapp.run(rp)
    keep = [i for i, t in enumerate(wall) if t - t0 > 1][1:]  # skip the first second
    Path(out).write_text(json.dumps({
        "wall": [(wall[i] - wall[i - 1]) * 1000 for i in keep],
        "cpu": [(cpu[i] - cpu[i - 1]) * 1000 for i in keep]}))


def run_empty(size: str, seconds: float) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "empty.json"
        subprocess.run([shutil.which("xvfb-run"), "-a", "-s", "-screen 0 1920x1200x24",
                        sys.executable, __file__, "--empty-window-child", out.as_posix(),
                        "--size", size, "--seconds", str(seconds), "x"], check=True,
                       capture_output=True)
        return json.loads(out.read_text())


def table(rep: dict, empty: dict | None = None) -> str:
    wall, cpu = dict(rep["frame_ms"]), dict(rep["frame_cpu_ms"])
    idle_med = float(np.median(wall["idle"]))
    idle_cpu = float(np.median(cpu["idle"]))
    phases = ["idle", "rendering", "dragging"]
    if empty is not None:
        wall["empty window"], cpu["empty window"] = empty["wall"], empty["cpu"]
        phases.insert(0, "empty window")
    lines = ["| phase | frames | median ms | p95 ms | max ms | median / idle | UI-thread CPU ms "
             "(median) | CPU / idle |", "|---|---|---|---|---|---|---|---|"]
    for phase in phases:
        w, c = np.asarray(wall[phase]), np.asarray(cpu[phase])
        if not len(w):
            lines.append(f"| {phase} | 0 | - | - | - | - | - | - |")
            continue
        lines.append(f"| {phase} | {len(w)} | {np.median(w):.1f} | {np.percentile(w, 95):.1f} | "
                     f"{w.max():.1f} | {np.median(w) / idle_med:.2f} | {np.median(c):.1f} | "
                     f"{np.median(c) / idle_cpu:.2f} |")
    return "\n".join(lines)


def level_table(rep: dict) -> str:
    rows = {}
    for _, level, ms, _, size in rep.get("levels", []):
        rows.setdefault((level, tuple(size)), []).append(ms)
    lines = ["| level | size (h, w) | renders | median ms |", "|---|---|---|---|"]
    for (level, size), ms in sorted(rows.items(), key=lambda kv: -kv[0][0]):
        lines.append(f"| 1/{level} | {size} | {len(ms)} | {np.median(ms):.0f} |")
    return "\n".join(lines)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("checkpoint", help="checkpoint.pt (its capture must exist)")
    p.add_argument("--seconds", type=float, default=10.0, help="seconds per phase (default 10)")
    p.add_argument("--res", type=int, default=256, help="neural render long side (default 256)")
    p.add_argument("--size", default="1280x800", help="window size (default 1280x800)")
    p.add_argument("--threads", type=int, default=None, help="torch threads of the worker (default 1)")
    p.add_argument("--nice", type=int, default=None,
                   help="niceness of the neural render thread (default: the viewer's, 10)")
    p.add_argument("--json", default=None, help="also write the raw report here")
    p.add_argument("--no-baseline", action="store_true",
                   help="skip the empty-window baseline row")
    p.add_argument("--empty-window-child", default=None, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.empty_window_child:
        empty_window_child(args.size, args.seconds, args.empty_window_child)
        return 0
    empty = None if args.no_baseline else run_empty(args.size, args.seconds)
    rep = run(args.checkpoint, args.seconds, args.res, args.size, args.threads, args.nice)
    if not rep.get("ok"):
        sys.exit(f"error: {rep.get('error', 'the bench did not finish')}")
    nice = "viewer default" if args.nice is None else args.nice
    print(f"viewer UI frame times, window {args.size}, neural render long side {args.res} px, "
          f"worker nice {nice}, {args.seconds:g} s per phase\n")
    print(table(rep, empty))
    print("\nneural render levels while the UI ran:\n")
    print(level_table(rep))
    if args.json:
        Path(args.json).write_text(json.dumps(rep, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
