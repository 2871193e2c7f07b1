"""The per-worker side of a parallel clip render: holds one model, renders frames.

A plain class so that it pickles by reference for any process pool; Ray wraps it as an
actor (:mod:`texvocab.pipeline.clip_ray`)."""

from __future__ import annotations

import numpy as np
import torch

from texvocab.io.images import to_uint8


class FrameWorker:
    """``render(i, pose, trans, camera) -> (i, (H, W, 3) uint8)`` with ``model`` and the
    march settings fixed; ``threads`` torch threads in this worker."""

    def __init__(self, model, march, scale: float, threads: int = 1):
        torch.set_num_threads(max(1, int(threads)))
        self.model, self.march, self.scale = model, march, float(scale)

    def render(self, i: int, pose, trans, camera) -> tuple[int, np.ndarray]:
        from texvocab.pipeline.evaluate import render_view

        rgb, _ = render_view(self.model, pose, trans, camera, self.march, self.scale)
        return i, to_uint8(rgb)
