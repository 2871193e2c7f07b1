"""The viewer's render workers without a window: how much a UI thread's Python work
slows the render when both share one interpreter (the thread worker, app/neural/worker.py)
against a render process of its own (app/neural/render_process.py), and the same view split
over two render processes (``process x2``, the viewer's default on 2 cores).

The "UI" here is a thread in this process that holds the GIL in pure Python for
``--ui-ms`` (default 25: the UI thread's CPU per frame while a slider is dragged,
bench/viewer_ui.py) and then sleeps ``--gap-ms`` (default 60: the rest of such a frame,
spent in GL and X outside the interpreter), so it takes under half a core: on a machine
whose cores are not all busy, what is left is the interpreter's lock. The same poses
(walk and squat alternating, 256 px long side, the camera of ``texvocab shot``) are
rendered coarse to fine, interleaved: each round runs both workers without and with the
UI load. Prints a table (median first level and full level, ratio to the same worker
without load) and a last line

    summary: thread_slowdown=… process_slowdown=… process_x2_slowdown=… split_speedup=…

(full-level time with the UI load over without, per worker; ``split_speedup``: one
process's full level over two processes', without load).

    .venv/bin/python bench/render_worker.py RUN/checkpoint.pt [--rounds 4]
"""

from __future__ import annotations

import argparse
import sys
import threading
import time

import numpy as np

from texvocab.pipeline import march_settings
from texvocab_viewer.gl.camera import DEFAULT_TARGET, OrbitCamera
from texvocab_viewer.neural.render_process import ProcessWorker
from texvocab_viewer.neural.worker import ProgressiveWorker, RenderJob, model_renderer
from texvocab_viewer.state import ViewerState, load_viewer_data

POSES = ("walk", "squat")


def ui_load(stop: threading.Event, hold_ms: float, gap_ms: float) -> None:
    """Hold the GIL in Python for ``hold_ms``, sleep ``gap_ms``, until ``stop``."""
    while not stop.is_set():
        t0, x = time.perf_counter(), 0
        while time.perf_counter() - t0 < hold_ms / 1000:
            for i in range(200):
                x += i
        time.sleep(gap_ms / 1000)


def timed_render(worker, job: RenderJob) -> tuple[float, float]:
    """(seconds to the job's first level, seconds to its last) as the UI polls them."""
    worker.poll()
    t0, first = time.perf_counter(), None
    worker.submit(job)
    while True:
        busy = worker.busy
        frame = worker.poll()
        if frame is not None and frame.version == job.version and first is None:
            first = time.perf_counter() - t0
        if not busy:
            break
        time.sleep(0.001)
    total = time.perf_counter() - t0
    return (total if first is None else first), total


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("checkpoint")
    p.add_argument(
        "--rounds",
        type=int,
        default=4,
        help="timed rounds (default 4; 2 renders per worker and load each, after one warm-up round)",
    )
    p.add_argument("--ui-ms", type=float, default=25.0)
    p.add_argument("--gap-ms", type=float, default=60.0)
    p.add_argument("--res", type=int, default=256, help="long side of the render (default 256)")
    args = p.parse_args()
    data = load_viewer_data(args.checkpoint, None)
    if data.model is None:
        sys.exit(f"error: {args.checkpoint}: not a checkpoint")
    state, march = ViewerState(data), march_settings(data.settings)
    workers = {
        "thread": ProgressiveWorker(model_renderer(data.model, march), threads=1),
        "process": ProcessWorker(model_renderer, (data.model, march), threads=1),
        "process x2": ProcessWorker(model_renderer, (data.model, march), threads=1, processes=2),
    }
    w, h = round(args.res * 132 / 256), args.res
    version = 0

    def job() -> RenderJob:
        nonlocal version
        version += 1
        state.reset_all()
        state.apply_preset(POSES[version % len(POSES)])
        cam = OrbitCamera(target=np.asarray(DEFAULT_TARGET) + state.trans, yaw=0.0, pitch=0.0, distance=3.2)
        return RenderJob(version, state.pose.copy(), state.trans.copy(), cam.to_texvocab_camera(w, h))

    times = {(name, load): [] for name in workers for load in ("none", "ui")}
    try:
        for rnd in range(args.rounds + 1):
            for load in ("none", "ui"):
                for name, worker in workers.items():
                    stop = threading.Event()
                    ui = threading.Thread(target=ui_load, args=(stop, args.ui_ms, args.gap_ms))
                    if load == "ui":
                        ui.start()
                    runs = [timed_render(worker, job()) for _ in range(2)]
                    stop.set()
                    if load == "ui":
                        ui.join()
                    if rnd > 0:  # the first round warms both workers up
                        times[(name, load)] += runs
    finally:
        for worker in workers.values():
            worker.stop()
    print(
        f"{w}x{h} renders, {args.rounds} rounds x 2 per cell; UI load: {args.ui_ms:g} ms of "
        f"Python, then {args.gap_ms:g} ms asleep, repeated\n"
    )
    print(
        "| worker | UI load | renders | first level ms (median) | full level s (median) | "
        "full / no load |\n|---|---|---|---|---|---|"
    )
    slowdown = {}
    for (name, load), runs in times.items():
        a = np.asarray(runs)
        base = np.median(np.asarray(times[(name, "none")])[:, 1])
        ratio = np.median(a[:, 1]) / base
        slowdown[name] = ratio if load == "ui" else slowdown.get(name, 1.0)
        print(
            f"| {name} | {load} | {len(a)} | {1000 * np.median(a[:, 0]):.0f} | "
            f"{np.median(a[:, 1]):.3f} | {ratio:.2f} |"
        )
    full = {name: np.median(np.asarray(times[(name, "none")])[:, 1]) for name in workers}
    print(
        f"\nsummary: thread_slowdown={slowdown['thread']:.2f} "
        f"process_slowdown={slowdown['process']:.2f} "
        f"process_x2_slowdown={slowdown['process x2']:.2f} "
        f"split_speedup={full['process'] / full['process x2']:.2f}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
