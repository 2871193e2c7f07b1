"""The viewer's camera: orbit about the world's up axis or a capture camera as a preset,
framing the body, and follow mode (the camera moves with the root)."""

from __future__ import annotations

import numpy as np

from texvocab.errors import TexvocabError
from texvocab_viewer.gl.camera import CaptureViewCamera, OrbitCamera, orbit_for


class CameraControls:
    """Mixed into the Viewer: ``camera``, ``follow`` and the 3D view's ``view_size`` over
    ``state`` (the pose) and ``data`` (the capture's cameras)."""

    def root_position(self) -> np.ndarray:
        """(3,) world position of the root joint (pelvis) in the current pose."""
        return self.state.posed()[1][0].astype(np.float64)

    def set_follow(self, on: bool) -> None:
        """Follow mode: the camera moves with the root. Turning it on centres the root
        horizontally in an orbit view (its height offset is kept); a capture view keeps
        its framing and moves along."""
        self.follow = bool(on)
        root = self.root_position()
        if isinstance(self.camera, CaptureViewCamera):
            self._follow_ref = root - self.camera.shift
        else:
            self._follow_ref = np.array([0.0, self.camera.target[1] - root[1], 0.0])
        self.follow_root()

    def follow_root(self) -> None:
        if not self.follow:
            return
        root = self.root_position()
        if isinstance(self.camera, CaptureViewCamera):
            self.camera.shift = root - self._follow_ref
        else:
            self.camera.target = root + self._follow_ref

    def set_capture_view(self, index: int | None) -> None:
        """Look through capture camera ``index`` (as ``texvocab shot --camera N``), or with
        None go back to the orbit camera (from the capture camera's place)."""
        cap = self.data.capture
        if index is None:
            if isinstance(self.camera, CaptureViewCamera):
                self.camera = self.camera.to_orbit(self.body_centre())
        else:
            if cap is None or not 0 <= index < cap.num_views:
                raise TexvocabError(f"camera {index}: no such capture view")
            self.camera = CaptureViewCamera(cap.cameras[index], index)
        if self.follow:
            self.set_follow(True)

    def orbit_camera(self) -> OrbitCamera:
        """The orbit camera, leaving a capture view for the nearest orbit (a drag in the
        3D view does this)."""
        if isinstance(self.camera, CaptureViewCamera):
            self.set_capture_view(None)
        return self.camera

    def body_centre(self) -> np.ndarray:
        verts, _ = self.state.posed()
        return (verts.min(0) + verts.max(0)).astype(np.float64) / 2.0

    def neural_aspect(self) -> float:
        """Width / height of the neural render: the capture camera's, or the 3D view's."""
        if isinstance(self.camera, CaptureViewCamera):
            return self.camera.aspect
        return self.view_aspect()

    def new_orbit(self) -> OrbitCamera:
        """An orbit camera about the world's up axis (:func:`orbit_for`)."""
        return orbit_for(self.data.capture)

    def reset_camera(self, aspect: float | None = None) -> None:
        """Frame the body of the current pose from the front, in a view of width / height
        ``aspect`` (default: the 3D view's)."""
        if isinstance(self.camera, CaptureViewCamera):
            self.camera = self.new_orbit()
        aspect = self.view_aspect() if aspect is None else aspect
        verts, _ = self.state.posed()
        local = verts @ self.camera.basis.T  # right, up, front (x, y, z when +y is up)
        lo, hi = local.min(0), local.max(0)
        self.camera.target = ((lo + hi) / 2.0) @ self.camera.basis
        self.camera.yaw, self.camera.pitch = 0.0, 0.0
        half = np.tan(np.radians(self.camera.fov) / 2)
        need = max((hi[1] - lo[1]) / (2 * half), (hi[0] - lo[0]) / (2 * half * aspect))
        self.camera.distance = 1.12 * float(need) + float(hi[2] - lo[2]) / 2
        if self.follow:
            self.set_follow(True)

    def view_aspect(self) -> float:
        w, h = self.view_size
        return w / max(h, 1)
