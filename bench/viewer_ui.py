"""The viewer as a user runs it, under Xvfb (Mesa llvmpipe, 2 cores): what the idle UI
costs, how fast the neural render reaches the screen in the window against
``texvocab shot`` rendering the same pose from the same camera at the same size, and
frame times while a slider is dragged.

Runs ``python -m app.window CHECKPOINT --script bench:SECONDS:RES`` under xvfb-run (the
driver in app/bench_driver.py), then ``texvocab shot CHECKPOINT --pose P --camera 0,0,3.2
--size WxH`` for each pose the window rendered, one after the other (nothing else
running). Prints three tables and a last line

    summary: idle_ui_cpu_share=… window_full_s=… shot_s=… window_over_shot=… first_level_ms=…

(medians over the renders; issue targets: idle share <= 0.10 of a core, window / shot
<= 1.5, first level <= 50 ms).

    .venv/bin/python bench/viewer_ui.py RUN/checkpoint.pt [--seconds 10] [--res 256]

A first row times an empty hello_imgui window of the same size at full speed: what GL
under llvmpipe and the X server cost per frame before the viewer draws anything.
"""
from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
TEXVOCAB = Path(sys.executable).parent / "texvocab"


def run_window(checkpoint: str, seconds: float, res: int, size: str, threads: int | None,
               nice: int | None) -> dict:
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
            sys.exit(f"error: the window wrote no report (rc {proc.returncode}):\n"
                     f"{proc.stderr[-3000:]}")
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


def run_shot(checkpoint: str, pose: str, size: tuple[int, int]) -> float:
    """Seconds ``texvocab shot`` took for the neural render (its own printed timing)."""
    with tempfile.TemporaryDirectory() as tmp:
        proc = subprocess.run([str(TEXVOCAB), "shot", checkpoint, "--pose", pose, "--camera",
                               "0,0,3.2", "--size", f"{size[0]}x{size[1]}", "--out", tmp],
                              cwd=ROOT, capture_output=True, text=True)
    found = re.search(r"neural render in ([0-9.]+) s", proc.stdout)
    if proc.returncode or not found:
        sys.exit(f"error: texvocab shot failed (rc {proc.returncode}):\n{proc.stderr[-2000:]}")
    return float(found.group(1))


def render_table(renders: list[dict], shot_s: dict[str, float]) -> tuple[str, list[float]]:
    lines = ["| render | pose | size (h, w) | 1/8 on screen ms | 1/4 ms | 1/2 ms | full s | "
             "shot s | window / shot | UI CPU share | render CPU share |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    ratios = []
    for i, r in enumerate(renders):
        at = {lv["level"]: lv["on_screen_s"] for lv in r["levels"]}
        size = r["levels"][-1]["size"] if r["levels"] else "-"
        full = at.get(1, float("nan"))
        ratio = full / shot_s[r["pose"]]
        ratios.append(ratio)
        cells = [f"{1000 * at[lv]:.0f}" if lv in at else "-" for lv in (8, 4, 2)]
        lines.append(f"| {i + 1} | {r['pose']} | {size} | {' | '.join(cells)} | {full:.2f} | "
                     f"{shot_s[r['pose']]:.2f} | {ratio:.2f} | {r['ui_cpu_share']:.2f} | "
                     f"{r['render_cpu_share']:.2f} |")
    return "\n".join(lines), ratios


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("checkpoint", help="checkpoint.pt (its capture must exist)")
    p.add_argument("--seconds", type=float, default=10.0,
                   help="seconds of the idle and dragging phases (default 10)")
    p.add_argument("--res", type=int, default=256, help="neural render long side (default 256)")
    p.add_argument("--size", default="1280x800", help="window size (default 1280x800)")
    p.add_argument("--threads", type=int, default=None,
                   help="torch threads of the render worker (default: the viewer's)")
    p.add_argument("--nice", type=int, default=None,
                   help="niceness of the neural render thread (default: the viewer's)")
    p.add_argument("--json", default=None, help="also write the raw report here")
    p.add_argument("--no-baseline", action="store_true",
                   help="skip the empty-window row (what GL and X cost with nothing drawn)")
    p.add_argument("--empty-window-child", default=None, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.empty_window_child:
        empty_window_child(args.size, args.seconds, args.empty_window_child)
        return 0
    empty = None if args.no_baseline else run_empty(args.size, args.seconds)
    rep = run_window(args.checkpoint, args.seconds, args.res, args.size, args.threads, args.nice)
    if not rep.get("ok"):
        sys.exit(f"error: {rep.get('error', 'the bench did not finish')}")
    renders = rep["renders"]
    sizes = {r["pose"]: tuple(r["levels"][-1]["size"]) for r in renders if r["levels"]}
    shot_s = {pose: run_shot(args.checkpoint, pose, (hw[1], hw[0])) for pose, hw in sizes.items()}
    idle = rep["idle"]
    print(f"viewer {args.size} under Xvfb, neural render long side {args.res} px, render "
          f"threads {rep.get('neural_threads')}, {args.seconds:g} s idle\n")
    print("| phase | seconds | frames | UI CPU share (cores) |\n|---|---|---|---|")
    print(f"| idle | {idle['seconds']:.1f} | {idle['frames']} | {idle['ui_cpu_share']:.3f} |")
    table, ratios = render_table(renders, shot_s)
    print("\nneural render in the window (time after the pose change at which each level "
          "was on screen) against texvocab shot, same pose, camera and size:\n")
    print(table)
    drag = np.asarray(rep["dragging"]["frame_ms"])
    cpu = np.asarray(rep["dragging"]["cpu_ms"])
    print("\n| window at full speed | frames | median ms | p95 ms | UI-thread CPU ms (median) |")
    print("|---|---|---|---|---|")
    rows = [("dragging a slider", drag, cpu)]
    if empty is not None:
        rows.insert(0, ("empty hello_imgui window (baseline)", np.asarray(empty["wall"]),
                        np.asarray(empty["cpu"])))
    for name, ms, c in rows:
        if len(ms):
            print(f"| {name} | {len(ms)} | {np.median(ms):.1f} | {np.percentile(ms, 95):.1f} | "
                  f"{np.median(c):.1f} |")
    if args.json:
        Path(args.json).write_text(json.dumps(rep, indent=1))
    full = [r["levels"][-1]["on_screen_s"] for r in renders if r["levels"]]
    first = [r["levels"][0]["on_screen_s"] * 1000 for r in renders if r["levels"]]
    print(f"\nsummary: idle_ui_cpu_share={idle['ui_cpu_share']:.3f} "
          f"window_full_s={np.median(full):.2f} shot_s={np.median(list(shot_s.values())):.2f} "
          f"window_over_shot={np.median(ratios):.2f} first_level_ms={np.median(first):.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
