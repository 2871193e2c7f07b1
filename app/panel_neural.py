"""Neural render panel: the trained avatar rendered by the CPU ray marcher in a worker
thread (:mod:`app.worker`), from the 3D view's camera, coarse to fine (1/8 .. 1), with
the level shown and how long it took. Without a checkpoint it says why it is empty.

Widget IDs: window "Neural render", ``**/Live``, ``**/resolution``, ``**/Render now``,
``**/preset``.
"""
from __future__ import annotations

from collections import deque

import numpy as np
from imgui_bundle import imgui

from app.worker import ProgressiveWorker, RenderFrame, RenderJob, model_renderer
from texvocab.pipeline import RENDER_PRESETS as PRESETS
from texvocab.pipeline import march_settings, render_overrides


class NeuralView:
    """The neural render's GUI state: the worker, the displayed level's GL texture, and
    the version counter bumped whenever pose, camera or resolution change."""

    def __init__(self, ctx, model, march, threads: int = 1, nice: int = 0, settings=None):
        self.ctx = ctx
        self.worker = ProgressiveWorker(model_renderer(model, march), threads=threads, nice=nice)
        self.settings = settings  # the checkpoint's Settings (for the presets)
        self.preset = "checkpoint"  # or a texvocab.pipeline.settings.PRESETS name
        self.march = None  # MarchSettings of the chosen preset (None: the checkpoint's)
        self.image_scale = 1.0
        self.live = True
        self.resolution = 256  # long side of the full-resolution level, pixels
        self.version = 0
        self._key = None
        self.frame: RenderFrame | None = None
        self.texture = None
        #: (version, level, milliseconds, seconds since the job started, (h, w)) per shown level
        self.history: deque[tuple] = deque(maxlen=200)

    @property
    def busy(self) -> bool:
        return self.worker.busy

    def size_for(self, aspect: float) -> tuple[int, int]:
        """(w, h) of the full-resolution level for a view of ``aspect``."""
        return _fit(max(8, round(self.resolution * self.image_scale)), aspect)

    def update(self, state, camera, aspect: float, force: bool = False) -> None:
        """Submit a job when the pose, camera or size changed; upload a new level."""
        w, h = self.size_for(aspect)
        key = (state.version, camera_key(camera), w, h, self.preset)
        if (self.live and key != self._key) or force:
            self._key = key
            self.version += 1
            self.worker.submit(RenderJob(self.version, state.pose.copy(), state.trans.copy(),
                                         camera.to_texvocab_camera(w, h), self.march))
        frame = self.worker.poll()
        if frame is not None:
            self._upload(frame)

    def set_preset(self, name: str) -> None:
        """Render with a speed/accuracy preset's render knobs (bench/tradeoff.py), or with
        the checkpoint's own settings ("checkpoint")."""
        self.preset = name
        if name == "checkpoint" or self.settings is None:
            self.march, self.image_scale = None, 1.0
            return
        s = render_overrides(self.settings, name, [])
        self.march, self.image_scale = march_settings(s), s.image_scale

    def _upload(self, frame: RenderFrame) -> None:
        img = np.ascontiguousarray((np.clip(frame.image, 0, 1) * 255 + 0.5).astype(np.uint8))
        size = (img.shape[1], img.shape[0])
        if self.texture is None or self.texture.size != size:
            if self.texture is not None:
                self.texture.release()
            self.texture = self.ctx.texture(size, 3)
            self.texture.filter = (self.ctx.LINEAR, self.ctx.LINEAR)
        self.texture.write(img.tobytes())
        self.frame = frame
        self.history.append((frame.version, frame.level, frame.seconds * 1000, frame.elapsed,
                             img.shape[:2]))

    def close(self) -> None:
        self.worker.stop()
        if self.texture is not None:
            self.texture.release()
            self.texture = None


def _fit(long_side: int, aspect: float) -> tuple[int, int]:
    """(w, h) with the long side ``long_side`` and w / h = aspect (both >= 8)."""
    if aspect >= 1:
        return long_side, max(8, round(long_side / aspect))
    return max(8, round(long_side * aspect)), long_side


def camera_key(camera) -> tuple:
    return (float(camera.yaw), float(camera.pitch), float(camera.distance), float(camera.fov),
            *(float(v) for v in camera.target))


def status_line(frame: RenderFrame | None, busy: bool) -> str:
    if frame is None:
        return "rendering..." if busy else "waiting"
    level = "full resolution" if frame.level == 1 else f"1/{frame.level} resolution"
    h, w = frame.image.shape[:2]
    total = f"{frame.elapsed:.1f} s so far, refining..." if busy else f"{frame.elapsed:.1f} s in all"
    return f"{level} ({w}x{h}): {frame.seconds * 1000:.0f} ms; {total}"


def draw_neural_panel(viewer) -> None:
    """The "Neural render" window's contents."""
    nv = viewer.neural
    if nv is None:
        imgui.push_text_wrap_pos(0.0)
        imgui.text_disabled(viewer.neural_absent_reason())
        imgui.pop_text_wrap_pos()
        return
    _, nv.live = imgui.checkbox("Live", nv.live)
    if imgui.is_item_hovered():
        imgui.set_tooltip("re-render whenever the pose or the camera changes")
    imgui.same_line()
    imgui.set_next_item_width(120)
    _, nv.resolution = imgui.slider_int("resolution", nv.resolution, 64, 512, "%d px")
    imgui.same_line()
    force = imgui.button("Render now")
    names = ["checkpoint", *PRESETS]
    imgui.set_next_item_width(120)
    changed, index = imgui.combo("preset", names.index(nv.preset), names)
    if changed:
        nv.set_preset(names[index])
    if imgui.is_item_hovered():
        imgui.set_tooltip("speed/accuracy preset of the render knobs (bench/tradeoff.py)")
    nv.update(viewer.state, viewer.camera, viewer.view_aspect(), force)
    imgui.text(status_line(nv.frame, nv.busy))
    for err in list(nv.worker.errors)[-1:]:
        imgui.text_colored(imgui.ImVec4(1.0, 0.45, 0.4, 1.0), err)
    if nv.texture is None:
        return
    avail = imgui.get_content_region_avail()
    tw, th = nv.texture.size
    scale = min(avail.x / tw, avail.y / th) if avail.x > 0 and avail.y > 0 else 1.0
    imgui.image(imgui.ImTextureRef(nv.texture.glo), imgui.ImVec2(tw * scale, th * scale))
