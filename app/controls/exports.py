"""Exports from the 3D view's camera: Export video (the loaded sequence) and Screenshot
(the current pose), rendered in the background (:mod:`texvocab_viewer.export.job`); their
outcome goes to the status line."""

from __future__ import annotations

import numpy as np

from texvocab.pipeline import follow_camera, march_settings
from texvocab_viewer.export.job import Export
from texvocab_viewer.gl.camera import CaptureViewCamera


class ExportControls:
    """Mixed into the Viewer: ``export`` (the last job) from ``camera`` at
    :meth:`shot_size`."""

    def shot_size(self) -> tuple[int, int]:
        """Size of a screenshot: a capture camera's own image size (what ``texvocab shot
        --camera N`` writes), else the neural render's full level (the 3D view's size
        without a model)."""
        if isinstance(self.camera, CaptureViewCamera):
            return self.camera.camera.width, self.camera.camera.height
        if self.neural is not None:
            return self.neural.size_for(self.view_aspect())
        return self.view_size

    def start_export(self, poses, trans, stem: str, fps: float, view3d: bool = False) -> None:
        """Render ``poses`` (T, 24, 3) from the 3D view's camera at :meth:`shot_size` in
        the background (texvocab_viewer.export.job): an MP4, or for one pose neural.png (+ view3d.png, the
        3D view at the same size, when ``view3d``; only that without a model)."""
        w, h = self.shot_size()
        camera = self.camera.to_texvocab_camera(w, h)
        if self.follow and len(poses) > 1:  # the camera moves with the root, as in the view
            camera = follow_cameras(camera, np.asarray(trans), self.state.trans)
        image = None
        if view3d:
            self.scene.render(self.state, self.camera, (w, h), self.options)
            image = self.scene.read((w, h))
            self.ctx.screen.use()
        model, march = None, None
        if self.neural is not None:
            model = self.data.model
            march = self.neural.march or march_settings(self.data.settings)
        self.export = Export(
            model,
            march,
            camera,
            np.asarray(poses),
            np.asarray(trans),
            stem,
            fps,
            image,
            background=self.options.background,
        )

    def screenshot(self) -> None:
        """The Screenshot button and F12: the 3D view and the neural render of the current
        pose, written under exports/shot*/ (never replacing a file)."""
        if self.export is None or not self.export.running:
            self.start_export(self.state.pose[None], self.state.trans[None], "shot", 1.0, view3d=True)


def follow_cameras(camera, trans: np.ndarray, now: np.ndarray) -> list:
    """One camera per frame of root translations ``trans`` (T, 3): ``camera`` (the view
    at root translation ``now``) moved with the root, as follow mode moves the view (the
    root joint is its rest position plus the translation)."""
    return [follow_camera(camera, t - np.asarray(now, np.float64)) for t in trans]
