"""Steps the scripted runs share (ImGui Test Engine scripts, :mod:`.scripts` and
:mod:`.daily_scripts`): the pose change they make, what the vocabulary panel drew, and
waits for the neural render and for an export."""

from __future__ import annotations

import time

from imgui_bundle import hello_imgui

LEFT_ARM_MOVE = ("**/left_shoulder/##z", -70.0)  # lower the left arm from the T-pose


def snapshot(viewer) -> dict:
    """What the vocabulary panel last drew, per part: [(key id, frame, weight)], the
    parts' nearest-key distances, the parts it highlighted as moved and each key's
    distance bar [(key id, length)]."""
    return {
        "keys": {p: [list(k) for k in v] for p, v in viewer.drawn_keys.items()},
        "novelty": {q.part: float(q.novelty) for q in viewer.state.query()},
        "moved": list(viewer.drawn_moved),
        "distance_bars": {p: [list(b) for b in v] for p, v in viewer.drawn_distances.items()},
    }


def wait_neural(ctx, viewer, report: dict, timeout: float = 60.0) -> None:
    """Yield frames until the neural render reached full resolution (or ``timeout``)."""
    if viewer.neural is None:
        return
    t0 = time.perf_counter()
    ctx.yield_(2)
    while (viewer.neural.busy or viewer.neural.frame is None) and time.perf_counter() - t0 < timeout:
        ctx.yield_()
    ctx.yield_(2)
    log = list(viewer.idling_log)  # (worker busy, playing, idling enabled) per frame so far
    report["idling_while_busy"] = sorted({idle for busy, play, idle in log if busy and not play})
    report["idling_while_playing"] = sorted({idle for _, play, idle in log if play})
    report["idling_when_done"] = bool(hello_imgui.get_runner_params().fps_idling.enable_idling)
    f = viewer.neural.frame
    report["neural"] = (
        None
        if f is None
        else {
            "level": f.level,
            "ms": f.seconds * 1000,
            "size": list(f.image.shape[:2]),
            "corner": [float(c) for c in f.image[0, 0]],
            "delivered": [list(d) for d in viewer.neural.worker.delivered],
            "errors": list(viewer.neural.worker.errors),
            "traceback": viewer.neural.worker.last_traceback,
        }
    )


def wait_export(ctx, viewer, timeout: float = 120.0) -> dict:
    t0 = time.perf_counter()
    ctx.yield_(2)
    while viewer.export is not None and viewer.export.running and time.perf_counter() - t0 < timeout:
        ctx.yield_()
    ctx.yield_(2)
    job = viewer.export
    return {
        "path": None if job is None or job.path is None else str(job.path.resolve()),
        "error": None if job is None else job.error,
        "frames": None if job is None else job.done,
    }
