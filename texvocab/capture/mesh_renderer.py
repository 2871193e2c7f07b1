"""Offscreen mesh rendering with pyrender over OSMesa/EGL (demo pictures, synthetic captures).

Cameras follow the project convention (OpenCV): ``x_cam = R @ x_world + t``, +z forward,
+y down, intrinsics ``K`` in pixels.
"""

from __future__ import annotations

import logging

import numpy as np

from texvocab.capture.camera import look_at  # noqa: F401  (re-exported for callers here)
from texvocab.io.gl_platform import ensure_offscreen

ensure_offscreen()
import pyrender  # noqa: E402
import trimesh  # noqa: E402

# trimesh catches every exception in its vertex normals (a Ctrl-C included, which the
# command's stop flag still honours) and logs it with a traceback: its warnings are
# nothing a user can act on, and the command's own `error:` line must stay the only one
logging.getLogger("trimesh").setLevel(logging.ERROR)

_CV_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])


def intrinsics(width: int, height: int, fov_y_deg: float) -> np.ndarray:
    """Pinhole K (3, 3) with the principal point at the image centre."""
    f = 0.5 * height / np.tan(np.radians(fov_y_deg) / 2)
    return np.array([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1]], dtype=np.float64)


def gl_principal_point(K: np.ndarray) -> tuple[float, float]:
    """pyrender's (cx, cy) for an OpenCV K: GL puts pixel centres at i + 0.5, OpenCV at i."""
    return float(K[0, 2]) + 0.5, float(K[1, 2]) + 0.5


def gl_camera_pose(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """pyrender camera-to-world (4, 4), GL axes, from OpenCV world-to-camera R, t."""
    w2c = np.eye(4)
    w2c[:3, :3], w2c[:3, 3] = R, t
    return np.linalg.inv(w2c) @ _CV_TO_GL


class MeshRenderer:
    """Reusable offscreen renderer for one image size.

    Args:
        width, height: image size in pixels.
        background: RGB in [0, 1].
    """

    def __init__(self, width: int, height: int, background=(1.0, 1.0, 1.0)):
        self.width, self.height = width, height
        self.background = np.asarray([*background, 0.0], dtype=np.float32)
        self._renderer = pyrender.OffscreenRenderer(width, height)

    def render(
        self, vertices, faces, K, R, t, vertex_colors=None, color=(0.62, 0.64, 0.72), flat: bool = False
    ) -> tuple[np.ndarray, np.ndarray]:
        """Render a triangle mesh.

        Args:
            vertices: (V, 3) world positions; faces: (F, 3).
            K, R, t: OpenCV camera.
            vertex_colors: optional (V, 3) RGB in [0, 1]; else a uniform ``color``.
            flat: no lighting (colours as given), for masks and label images.

        Returns:
            rgb (H, W, 3) float32 in [0, 1], depth (H, W) float32 metres (0 = background).
        """
        mesh = trimesh.Trimesh(np.asarray(vertices, np.float64), np.asarray(faces), process=False)
        if vertex_colors is not None:
            mesh.visual.vertex_colors = (np.clip(vertex_colors, 0, 1) * 255).astype(np.uint8)
        material = pyrender.MetallicRoughnessMaterial(
            baseColorFactor=[*color, 1.0], metallicFactor=0.0, roughnessFactor=0.8
        )
        scene = pyrender.Scene(bg_color=self.background, ambient_light=[0.35, 0.35, 0.35])
        scene.add(
            pyrender.Mesh.from_trimesh(
                mesh, material=None if vertex_colors is not None else material, smooth=True
            )
        )
        cam = pyrender.IntrinsicsCamera(K[0, 0], K[1, 1], *gl_principal_point(K), znear=0.05, zfar=100.0)
        pose = gl_camera_pose(R, t)
        scene.add(cam, pose=pose)
        scene.add(pyrender.DirectionalLight(color=np.ones(3), intensity=2.5), pose=pose)
        flags = pyrender.RenderFlags.FLAT if flat else pyrender.RenderFlags.NONE
        rgb, depth = self._renderer.render(scene, flags=flags)
        return rgb.astype(np.float32) / 255.0, depth.astype(np.float32)

    def close(self) -> None:
        self._renderer.delete()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
