"""Side-by-side panels for ``texvocab render --panels``: beside the neural render, the
viewer's 3D view of the same pose and camera with the pose's blended vocabulary texture
(``vocab``) or each part's novelty, its distance to the nearest key (``novelty``, Eq. 4),
rendered headless (OSMesa) as ``texvocab shot`` does."""

from __future__ import annotations

import numpy as np

from texvocab_viewer.gl.headless import create_headless_context, make_current, release
from texvocab_viewer.gl.scene import SceneOptions, SceneRenderer
from texvocab_viewer.state import ViewerData, ViewerState

PANELS = ("neural", "vocab", "novelty")
OPTIONS = {
    "vocab": SceneOptions(textured=True, lighting=False, background=(0.0, 0.0, 0.0)),
    "novelty": SceneOptions(novelty=True, background=(0.0, 0.0, 0.0)),
}


class GLPanels:
    """The GL panels of one clip: one OSMesa context and scene renderer for all frames.
    ``render(pose, trans, camera) -> [(H, W, 3) uint8 per panel]``; ``close()`` at the end."""

    def __init__(self, data: ViewerData, panels: list[str]):
        self.panels = [p for p in panels if p != "neural"]
        self.state = ViewerState(data)
        self.ctx = create_headless_context()
        make_current(self.ctx)
        self.renderer = SceneRenderer(self.ctx, data)

    def render(self, pose, trans, camera) -> list[np.ndarray]:
        self.state.set_pose(np.asarray(pose, np.float64), np.asarray(trans, np.float64))
        size = (camera.width, camera.height)
        images = []
        for name in self.panels:
            self.renderer.render(self.state, camera, size, OPTIONS[name])
            images.append(self.renderer.read(size))
        return images

    def close(self) -> None:
        self.renderer.release()
        release(self.ctx)


def side_by_side(images: list[np.ndarray]) -> np.ndarray:
    """(H, sum W, 3) uint8 of images (H, W_i, 3) left to right."""
    return np.concatenate([np.asarray(i, np.uint8) for i in images], axis=1)
