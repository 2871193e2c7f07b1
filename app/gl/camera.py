"""Orbit camera of the 3D view, and the one conversion between it, OpenGL matrices and the
project's OpenCV :class:`~texvocab.capture.Camera` (so the neural render and the GL view
of the same camera line up pixel for pixel).

GL and OpenCV differ in two ways handled here only: camera axes (GL looks down -z with
+y up, OpenCV down +z with +y down) and pixel centres (GL at i + 0.5, OpenCV at i).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from texvocab.pipeline import Camera, capture_up, look_at, needs_placing, stand_point, toward

CV_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])  # OpenCV camera axes -> GL camera axes
DEFAULT_TARGET = (0.0, -0.3, 0.0)  # the default body's centre (its synthetic captures aim here)


def gl_projection_from_K(K: np.ndarray, width: int, height: int, near: float, far: float) -> np.ndarray:
    """(4, 4) clip-space matrix for OpenCV camera coordinates (x right, y down, z forward).

    OpenCV pixel (u, v) with centres at integers maps to GL window pixel (u + 0.5,
    H - v - 0.5) (bottom-up rows). Depth maps [near, far] to NDC [-1, 1].
    """
    fx, s, cx = K[0]
    fy, cy = K[1, 1], K[1, 2]
    return np.array(
        [
            [2 * fx / width, 2 * s / width, 2 * (cx + 0.5) / width - 1, 0.0],
            [0.0, -2 * fy / height, 1 - 2 * (cy + 0.5) / height, 0.0],
            [0.0, 0.0, (far + near) / (far - near), -2 * far * near / (far - near)],
            [0.0, 0.0, 1.0, 0.0],
        ]
    )


def gl_mvp(camera: Camera, near: float = 0.05, far: float = 100.0) -> np.ndarray:
    """(4, 4) world -> clip matrix for drawing what ``camera`` sees at its image size."""
    extr = np.eye(4)
    extr[:3, :3], extr[:3, 3] = camera.R, camera.t
    return gl_projection_from_K(camera.K, camera.width, camera.height, near, far) @ extr


@dataclass
class OrbitCamera:
    """Camera on a sphere around ``target``.

    Attributes:
        target: (3,) world point looked at, metres.
        yaw: degrees about +y; 0 looks at the body's front (camera on +z).
        pitch: degrees above the horizontal, in (-89, 89).
        distance: metres from the target; fov: vertical field of view, degrees.
        up: (3,) the world's up axis (+y; a capture's own, ZJU-MoCap's −z); front: (3,)
            where yaw 0 puts the camera, normal to ``up`` (+z).
    """

    target: np.ndarray = field(default_factory=lambda: np.array(DEFAULT_TARGET))
    yaw: float = 0.0
    pitch: float = 0.0
    distance: float = 3.2
    fov: float = 40.0
    near: float = 0.05
    far: float = 100.0
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    front: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))

    def __post_init__(self):
        self.target = np.asarray(self.target, dtype=np.float64).reshape(3)
        self.up = np.asarray(self.up, dtype=np.float64).reshape(3)
        self.up = self.up / np.linalg.norm(self.up)
        f = np.asarray(self.front, dtype=np.float64).reshape(3)
        f = f - np.dot(f, self.up) * self.up
        self.front = f / np.linalg.norm(f)

    @property
    def basis(self) -> np.ndarray:
        """(3, 3) rows: the world's right, up and front axes of the orbit (x, y, z for +y up)."""
        return np.stack([np.cross(self.up, self.front), self.up, self.front])

    @property
    def eye(self) -> np.ndarray:
        """(3,) camera centre in world coordinates."""
        yaw, pitch = np.radians(self.yaw), np.radians(self.pitch)
        offset = np.array([np.cos(pitch) * np.sin(yaw), np.sin(pitch), np.cos(pitch) * np.cos(yaw)])
        return self.target + self.distance * offset @ self.basis

    def orbit(self, dx: float, dy: float) -> None:
        """Turn by ``dx`` degrees of yaw and ``dy`` degrees of pitch (clamped to ±89°)."""
        self.yaw = (self.yaw + dx + 180.0) % 360.0 - 180.0
        self.pitch = float(np.clip(self.pitch + dy, -89.0, 89.0))

    def zoom(self, factor: float) -> None:
        """Multiply the distance by ``factor`` (> 0), kept within [0.2, 50] metres."""
        self.distance = float(np.clip(self.distance * factor, 0.2, 50.0))

    def pan(self, dx: float, dy: float) -> None:
        """Move the target in the image plane by fractions of the view height (dx right,
        dy up), so a drag across the view moves the scene about as far."""
        R, _ = look_at(self.eye, self.target, self.up)
        scale = 2.0 * self.distance * np.tan(np.radians(self.fov) / 2)
        self.target = self.target + scale * (dx * R[0] - dy * R[1])

    def view_matrix(self) -> np.ndarray:
        """(4, 4) world -> GL camera (looks down -z, +y up)."""
        R, t = look_at(self.eye, self.target, self.up)
        extr = np.eye(4)
        extr[:3, :3], extr[:3, 3] = R, t
        return CV_TO_GL @ extr

    def projection(self, aspect: float) -> np.ndarray:
        """(4, 4) GL perspective projection for width / height = ``aspect``."""
        f = 1.0 / np.tan(np.radians(self.fov) / 2)
        n, fa = self.near, self.far
        return np.array(
            [
                [f / aspect, 0, 0, 0],
                [0, f, 0, 0],
                [0, 0, (fa + n) / (n - fa), 2 * fa * n / (n - fa)],
                [0, 0, -1, 0],
            ]
        )

    def intrinsics(self, width: int, height: int) -> np.ndarray:
        """OpenCV K (3, 3): vertical fov ``fov``, principal point at the image centre."""
        f = 0.5 * height / np.tan(np.radians(self.fov) / 2)
        return np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1.0]])

    def to_texvocab_camera(self, width: int, height: int) -> Camera:
        """The same view as an OpenCV :class:`Camera` of ``width`` × ``height`` pixels."""
        R, t = look_at(self.eye, self.target, self.up)
        return Camera(self.intrinsics(width, height), R, t, width, height, name="orbit")

    @classmethod
    def from_capture_camera(cls, cam: Camera, target=None) -> OrbitCamera:
        """The orbit camera closest to a capture camera: same centre, same viewing axis
        (looking at the point of the axis nearest to ``target``, default the body centre)
        and vertical fov. Exact for cameras without roll and with a centred principal
        point (synthetic captures); others lose their roll and principal-point offset."""
        centre = cam.center
        forward = cam.R[2] / np.linalg.norm(cam.R[2])
        ref = np.asarray(DEFAULT_TARGET if target is None else target, dtype=np.float64)
        dist = max(float(np.dot(ref - centre, forward)), 0.2)
        look = centre + dist * forward
        offset = (centre - look) / dist
        pitch = float(np.degrees(np.arcsin(np.clip(offset[1], -1.0, 1.0))))
        yaw = float(np.degrees(np.arctan2(offset[0], offset[2])))
        fov = float(np.degrees(2 * np.arctan(0.5 * cam.height / cam.K[1, 1])))
        return cls(target=look, yaw=yaw, pitch=pitch, distance=dist, fov=fov)


@dataclass
class CaptureViewCamera:
    """One of the capture's own cameras, as a preset of the 3D view: drawn and rendered
    exactly as ``texvocab shot --camera N`` does (its K, R, t), scaled to the view's
    size with its aspect ratio kept (the view is letterboxed). ``shift`` (3,) moves it
    with the body in follow mode. Dragging turns it into the nearest :class:`OrbitCamera`.
    """

    camera: Camera
    index: int
    shift: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def aspect(self) -> float:
        return self.camera.width / self.camera.height

    def moved(self) -> Camera:
        """The capture camera moved by ``shift`` (same orientation and intrinsics)."""
        centre = self.camera.center + self.shift
        c = self.camera
        return Camera(c.K, c.R, -c.R @ centre, c.width, c.height, c.dist, c.name)

    def to_texvocab_camera(self, width: int, height: int) -> Camera:
        """The camera at ``width`` (its height follows from the aspect ratio; ``height``
        must agree to one pixel)."""
        cam = self.moved()
        if width == cam.width:
            return cam
        factor = width / cam.width
        if abs(cam.height * factor - height) > 1.0:
            raise ValueError(
                f"capture view {self.index} is {cam.width}x{cam.height}; cannot "
                f"draw it at {width}x{height} (different aspect ratio)"
            )
        return cam.scaled(factor)

    def key(self) -> tuple:
        return ("view", self.index, *(float(v) for v in self.shift))

    def to_orbit(self, target) -> OrbitCamera:
        return OrbitCamera.from_capture_camera(self.moved(), target)


def fit_aspect(width: int, height: int, aspect: float) -> tuple[int, int]:
    """The largest (w, h) inside ``width`` × ``height`` with w / h = ``aspect``."""
    if width / max(height, 1) > aspect:
        return max(1, round(height * aspect)), max(1, height)
    return max(1, width), max(1, round(width / aspect))


def orbit_for(capture) -> OrbitCamera:
    """An orbit camera about the world's up axis: +y, or a capture's own when it is not
    (ZJU-MoCap's −z; :mod:`texvocab.pipeline.clip_placement`), yaw 0 towards its camera 0."""
    if capture is None or not needs_placing(capture, "auto"):
        return OrbitCamera()
    up = capture_up(capture)
    return OrbitCamera(up=up, front=toward(capture.cameras[0], stand_point(capture), up))
