"""The viewer as a user runs it, under Xvfb (Mesa llvmpipe, 2 cores): what the idle UI
costs, how fast the neural render reaches the screen in the window against
``texvocab shot`` rendering the same pose from the same camera at the same size, and
frame times while a slider is dragged.

Runs ``python -m texvocab_viewer CHECKPOINT --script bench:SECONDS:RES`` under xvfb-run (the
driver in app/testing/bench.py), then ``texvocab shot CHECKPOINT --pose P --camera 0,0,3.2
--size WxH`` for each pose the window rendered, one after the other (nothing else
running). Prints tables (per render, their spread, frames, panels) and a last line

    summary: worker=… idle_ui_cpu_share=… window_full_s=… shot_s=… window_over_shot=…
             first_level_ms=… dragging_frame_ms=… renders=… first_level_p75_ms=…
             first_within_target=k/N full_within_target=k/N preview_in_pose_frame=k/N
             drag_preview_age_frames_p95=… drag_frames_within_1=k/N drag_frame_ms_p95=…
             after_drag_full_s=… after_drag_each_s=…

(medians over the renders, for the first worker run; issue targets: idle share <= 0.10
of a core, window / shot <= 1.5, first level <= 50 ms, full level <= 0.5 s, UI frames
while rendering <= 33 ms). ``--worker both`` (the default) runs the window with its
render process and again with the render thread, one after the other.

    .venv/bin/python bench/viewer_ui.py RUN/checkpoint.pt [--seconds 10] [--res 256]

A first row times an empty hello_imgui window of the same size at full speed, with the
viewer's framebuffer (no MSAA): what GL under llvmpipe and the X server cost per frame
before the viewer draws anything.
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
from empty_window import run_empty

from texvocab_viewer.testing.bench import RENDERS, drag_stats  # pose changes timed per worker

ROOT = Path(__file__).resolve().parent.parent
FIRST_TARGET_MS, FULL_TARGET_S = 50.0, 0.5  # the viewer's targets: first level, full level
TEXVOCAB = Path(sys.executable).parent / "texvocab"


def run_window(
    checkpoint: str,
    seconds: float,
    res: int,
    size: str,
    threads: int | None,
    nice: int | None,
    worker: str,
    renders: int,
    preview_wait: float | None = None,
    rest_levels: str = "",
) -> dict:
    xvfb = shutil.which("xvfb-run")
    if xvfb is None:
        sys.exit("error: xvfb-run is missing (apt-get install xvfb xauth)")
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "bench.json"
        cmd = [
            xvfb,
            "-a",
            "-s",
            "-screen 0 1920x1200x24",
            sys.executable,
            "-m",
            "texvocab_viewer",
            checkpoint,
            "--size",
            size,
            "--script",
            f"bench:{seconds}:{res}:{renders}:{rest_levels.replace(',', '-')}",
            "--report",
            str(report),
            "--neural-worker",
            worker,
        ]
        if threads:
            cmd += ["--neural-threads", str(threads)]
        if nice is not None:
            cmd += ["--neural-nice", str(nice)]
        if preview_wait is not None:
            cmd += ["--neural-preview-wait", str(preview_wait)]
        proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
        if not report.is_file():
            sys.exit(f"error: the window wrote no report (rc {proc.returncode}):\n{proc.stderr[-3000:]}")
        return json.loads(report.read_text())


def run_shot(checkpoint: str, pose: str, size: tuple[int, int]) -> float:
    """Seconds ``texvocab shot`` took for the neural render (its own printed timing)."""
    with tempfile.TemporaryDirectory() as tmp:
        proc = subprocess.run(
            [
                str(TEXVOCAB),
                "shot",
                checkpoint,
                "--pose",
                pose,
                "--camera",
                "0,0,3.2",
                "--size",
                f"{size[0]}x{size[1]}",
                "--out",
                tmp,
            ],
            cwd=ROOT,
            capture_output=True,
            text=True,
        )
    found = re.search(r"neural render in ([0-9.]+) s", proc.stdout)
    if proc.returncode or not found:
        sys.exit(f"error: texvocab shot failed (rc {proc.returncode}):\n{proc.stderr[-2000:]}")
    return float(found.group(1))


def render_table(runs: dict[str, list[dict]], shot_s: dict[str, float]) -> tuple[str, dict]:
    """One row per render of each worker; the window / shot ratios per worker."""
    lines = [
        "| worker | render | pose | size (h, w) | 1/8 on screen ms | 1/4 ms | 1/2 ms | "
        "full s | shot s | window / shot | UI CPU share | render CPU share |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    ratios = {}
    for worker, renders in runs.items():
        ratios[worker] = _render_rows(worker, renders, shot_s, lines)
    return "\n".join(lines), ratios


def _render_rows(worker: str, renders: list[dict], shot_s: dict[str, float], lines: list[str]) -> list[float]:
    ratios = []
    for i, r in enumerate(renders):
        at = {lv["level"]: lv["on_screen_s"] for lv in r["levels"]}
        size = r["levels"][-1]["size"] if r["levels"] else "-"
        full = at.get(1, float("nan"))
        ratio = full / shot_s[r["pose"]]
        ratios.append(ratio)
        cells = [f"{1000 * at[lv]:.0f}" if lv in at else "-" for lv in (8, 4, 2)]
        lines.append(
            f"| {worker} | {i + 1} | {r['pose']} | {size} | {' | '.join(cells)} | {full:.2f} | "
            f"{shot_s[r['pose']]:.2f} | {ratio:.2f} | {r['ui_cpu_share']:.2f} | "
            f"{r['render_cpu_share']:.2f} |"
        )
    return ratios


def _spread(a: np.ndarray, fmt: str) -> str:
    """'median (p25-p75, max)'."""
    p25, med, p75 = np.percentile(a, [25, 50, 75])
    return f"{med:{fmt}} ({p25:{fmt}}-{p75:{fmt}}, {a.max():{fmt}})"


def spread_table(runs: dict[str, list[dict]]) -> str:
    """Per worker, over its renders: when the first level and the full level were on
    screen (median, quartiles, worst; how many within the targets), and when the
    frame that changed the pose (the 3D view's) was."""
    lines = [
        "| worker | renders | first level on screen ms: median (p25-p75, max) | "
        f"within {FIRST_TARGET_MS:g} ms | full level s: median (p25-p75, max) | "
        f"within {FULL_TARGET_S:g} s | frame that changed the pose ms: median (max) | "
        "preview in that frame | its wait ms: median (max) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for worker, renders in runs.items():
        first = np.array([r["levels"][0]["on_screen_s"] * 1000 for r in renders if r["levels"]])
        full = np.array([r["levels"][-1]["on_screen_s"] for r in renders if r["levels"]])
        pose = np.array([r["pose_frame_s"] * 1000 for r in renders if "pose_frame_s" in r])
        if not len(first):
            continue
        lines.append(
            f"| {worker} | {len(first)} | {_spread(first, '.0f')} | "
            f"{int((first <= FIRST_TARGET_MS).sum())}/{len(first)} | "
            f"{_spread(full, '.2f')} | "
            f"{int((full <= FULL_TARGET_S).sum())}/{len(full)} | "
            f"{np.median(pose):.0f} ({pose.max():.0f}) | "
            f"{in_pose_frame(renders)}/{len(first)} | {_waits(renders)} |"
        )
    return "\n".join(lines)


def in_pose_frame(renders: list[dict]) -> int:
    """How many renders showed their first level in the frame that changed the pose."""
    return sum(
        1
        for r in renders
        if r["levels"] and "pose_frame_s" in r and r["levels"][0]["on_screen_s"] == r["pose_frame_s"]
    )


def _waits(renders: list[dict]) -> str:
    """'median (max)' of the pose frames' waits for the preview ('-' when none waited)."""
    w = np.array([r["preview_wait"][0] for r in renders if r.get("preview_wait")])
    return f"{np.median(w):.0f} ({w.max():.0f})" if len(w) else "-"


def panel_table(reps: dict) -> str:
    """Per worker: the median UI-thread CPU of each panel per dragging frame (and the
    work before the panels: input, the render's submission and upload)."""
    names = sorted({n for rep in reps.values() for d in rep["dragging"].get("panel_cpu_ms", []) for n in d})
    lines = [
        "| worker | " + " | ".join(names) + " | all UI-thread CPU |",
        "|---|" + "---|" * (len(names) + 1),
    ]
    for w, rep in reps.items():
        frames = rep["dragging"].get("panel_cpu_ms", [])
        cells = [f"{np.median([d.get(n, 0.0) for d in frames]):.1f}" if frames else "-" for n in names]
        cpu = rep["dragging"]["cpu_ms"]
        lines.append(f"| {w} | " + " | ".join(cells) + f" | {np.median(cpu) if cpu else float('nan'):.1f} |")
    return "\n".join(lines)


def _drag_keys(rep: dict) -> str:
    """The dragging phase's summary keys (texvocab_viewer.testing.bench.drag_stats)."""
    d = drag_stats(rep)
    full = d["after_drag_full_s"]
    every = ",".join("none" if x is None else f"{x:.2f}" for x in d["after_drag_full_all_s"])
    return (
        f"drag_preview_age_frames_p95={d['drag_preview_age_frames_p95']:.1f} "
        f"drag_frames_within_1={d['drag_frames_within_1'][0]}/{d['drag_frames_within_1'][1]} "
        f"drag_frame_ms_p95={d['drag_frame_ms_p95']:.1f} "
        f"after_drag_full_s={'none' if full is None else f'{full:.2f}'} "
        f"after_drag_each_s={every or 'none'}"
    )


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("checkpoint", help="checkpoint.pt (its capture must exist)")
    p.add_argument(
        "--seconds", type=float, default=10.0, help="seconds of the idle and dragging phases (default 10)"
    )
    p.add_argument("--res", type=int, default=256, help="neural render long side (default 256)")
    p.add_argument("--size", default="1280x800", help="window size (default 1280x800)")
    p.add_argument(
        "--threads", type=int, default=None, help="torch threads of the render worker (default: the viewer's)"
    )
    p.add_argument(
        "--nice", type=int, default=None, help="niceness of the neural render thread (default: the viewer's)"
    )
    p.add_argument(
        "--preview-wait",
        type=float,
        default=None,
        metavar="MS",
        help="how long the frame that changes the pose waits for the preview "
        "(default: the viewer's; 0: the frame never waits)",
    )
    p.add_argument(
        "--renders",
        type=int,
        default=RENDERS,
        help=f"pose changes timed per worker (default {RENDERS}, walk and squat in turn)",
    )
    p.add_argument(
        "--worker",
        choices=("both", "process", "thread"),
        default="both",
        help="where the viewer renders: its render process (the default), a thread "
        "of the UI's interpreter (the previous default), or both, one after "
        "the other (default both; the summary line is the process's)",
    )
    p.add_argument(
        "--rest-levels",
        default="",
        metavar="L,L,...",
        help="the levels of a dragged pose's full render once the drag stops (default: the "
        "viewer's, the full level at once; 8,4,2,1 renders every level, as before)",
    )
    p.add_argument("--json", default=None, help="also write the raw reports here")
    p.add_argument(
        "--no-baseline",
        action="store_true",
        help="skip the empty-window row (what GL and X cost with nothing drawn)",
    )
    args = p.parse_args()
    empty = None if args.no_baseline else run_empty(args.size, args.seconds)
    workers = ("process", "thread") if args.worker == "both" else (args.worker,)
    reps = {}
    for worker in workers:
        rep = run_window(
            args.checkpoint,
            args.seconds,
            args.res,
            args.size,
            args.threads,
            args.nice,
            worker,
            args.renders,
            args.preview_wait,
            args.rest_levels,
        )
        if not rep.get("ok"):
            sys.exit(f"error: {worker} worker: {rep.get('error', 'the bench did not finish')}")
        reps[worker] = rep
    runs = {w: rep["renders"] for w, rep in reps.items()}
    sizes = {
        r["pose"]: tuple(r["levels"][-1]["size"]) for renders in runs.values() for r in renders if r["levels"]
    }
    shot_s = {pose: run_shot(args.checkpoint, pose, (hw[1], hw[0])) for pose, hw in sizes.items()}
    first_rep = reps[workers[0]]
    print(
        f"viewer {args.size} under Xvfb, neural render long side {args.res} px, render "
        f"threads {first_rep.get('neural_threads')}, {args.seconds:g} s idle\n"
    )
    print("| worker | phase | seconds | frames | UI CPU share (cores) |\n|---|---|---|---|---|")
    for worker, rep in reps.items():
        idle = rep["idle"]
        print(f"| {worker} | idle | {idle['seconds']:.1f} | {idle['frames']} | {idle['ui_cpu_share']:.3f} |")
        if "startup_s" in rep:
            print(f"| {worker} | first level after the window started | {rep['startup_s']:.1f} | - | - |")
        after = rep.get("after_render")
        if after:
            print(f"| {worker} | after the last render | {after['seconds']:.1f} | {after['frames']} | - |")
    table, ratios = render_table(runs, shot_s)
    print(
        "\nneural render in the window (time after the pose change at which each level "
        "was on screen) against texvocab shot, same pose, camera and size:\n"
    )
    print(table)
    print("\nthe same renders, spread:\n")
    print(spread_table(runs))
    print(
        "\n| window at full speed | frames | median ms | p95 ms | UI-thread CPU ms (median) | "
        "window-process CPU ms (UI + GL raster threads) |"
    )
    print("|---|---|---|---|---|---|")
    rows = [(f"dragging a slider ({w} worker)", rep["dragging"]) for w, rep in reps.items()]
    if empty is not None:
        rows.insert(
            0,
            (
                "empty hello_imgui window (baseline)",
                {
                    "frame_ms": empty["wall"],
                    "cpu_ms": empty["cpu"],
                    "process_cpu_ms": empty.get("process_cpu", []),
                },
            ),
        )
    for name, d in rows:
        ms = np.asarray(d["frame_ms"])
        proc = [x for x in d.get("process_cpu_ms", []) if x is not None]
        if len(ms):
            print(
                f"| {name} | {len(ms)} | {np.median(ms):.1f} | {np.percentile(ms, 95):.1f} | "
                f"{np.median(d['cpu_ms']):.1f} | "
                f"{np.median(proc) if proc else float('nan'):.1f} |"
            )
    print(
        "\n| worker | dragging s | neural images shown while dragging | per second | levels | "
        "ms from a job's start to its image (median) | shown pose's age in frames: median (p95) |"
    )
    print("|---|---|---|---|---|---|---|")
    for w, rep in reps.items():
        d = rep["dragging"]
        shown, secs = d.get("levels_shown", []), d.get("seconds", float("nan"))
        took, age = d.get("level_ms") or [np.nan], d.get("preview_age_frames") or [np.nan]
        print(
            f"| {w} | {secs:.1f} | {len(shown)} | {len(shown) / secs:.1f} | {sorted(set(shown))} | "
            f"{np.median(took):.0f} | {np.median(age):.0f} ({np.percentile(age, 95):.0f}) |"
        )
    print("\nwhere a dragging frame's UI-thread CPU goes (median ms per frame):\n")
    print(panel_table(reps))
    if args.json:
        Path(args.json).write_text(json.dumps(reps, indent=1))
    w = workers[0]
    full = [r["levels"][-1]["on_screen_s"] for r in runs[w] if r["levels"]]
    first = [r["levels"][0]["on_screen_s"] * 1000 for r in runs[w] if r["levels"]]
    drag = np.asarray(reps[w]["dragging"]["frame_ms"])
    print(
        f"\nsummary: worker={w} idle_ui_cpu_share={first_rep['idle']['ui_cpu_share']:.3f} "
        f"window_full_s={np.median(full):.2f} shot_s={np.median(list(shot_s.values())):.2f} "
        f"window_over_shot={np.median(ratios[w]):.2f} first_level_ms={np.median(first):.0f} "
        f"dragging_frame_ms={np.median(drag) if len(drag) else float('nan'):.1f} "
        f"renders={len(first)} first_level_p75_ms={np.percentile(first, 75):.0f} "
        f"first_within_target={sum(f <= FIRST_TARGET_MS for f in first)}/{len(first)} "
        f"full_within_target={sum(f <= FULL_TARGET_S for f in full)}/{len(full)} "
        f"preview_in_pose_frame={in_pose_frame(runs[w])}/{len(first)} {_drag_keys(reps[w])}"
    )

    return 0


if __name__ == "__main__":
    sys.exit(main())
