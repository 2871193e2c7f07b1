"""Pinhole camera in the OpenCV convention: ``x_cam = R @ x_world + t``, +z forward,
+y down, intrinsics ``K`` in pixels, optional distortion (k1, k2, p1, p2[, k3])."""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
import torch

#: every pixel's rays of the last few cameras (K, R, t, size, dtype): the viewer and a
#: bench render many frames from one camera, and the rays of 256² pixels took 2.2 ms
_EVERY_PIXEL: OrderedDict = OrderedDict()
_EVERY_PIXEL_KEPT = 4


@dataclass
class Camera:
    """One calibrated view.

    Attributes:
        K: (3, 3) intrinsics; R: (3, 3) rotation world->camera; t: (3,) translation, metres.
        width, height: image size in pixels.
        dist: (5,) OpenCV distortion (k1, k2, p1, p2, k3); zeros for an undistorted image.
        name: the view's name in its capture (e.g. ``Camera_B1``, ``cam00``).
    """

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    width: int
    height: int
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))
    name: str = ""

    def __post_init__(self):
        self.K = np.asarray(self.K, dtype=np.float64).reshape(3, 3)
        self.R = np.asarray(self.R, dtype=np.float64).reshape(3, 3)
        self.t = np.asarray(self.t, dtype=np.float64).reshape(3)
        d = np.asarray(self.dist, dtype=np.float64).reshape(-1)
        self.dist = np.concatenate([d, np.zeros(5 - len(d))]) if len(d) < 5 else d[:5]
        self.width, self.height = int(self.width), int(self.height)

    @property
    def center(self) -> np.ndarray:
        """(3,) camera centre in world coordinates."""
        return -self.R.T @ self.t

    def scaled(self, factor: float) -> "Camera":
        """The same camera for an image resized by ``factor`` (pixel centres kept aligned)."""
        K = self.K.copy()
        K[:2] *= factor
        K[:2, 2] += 0.5 * factor - 0.5
        return Camera(
            K, self.R, self.t, round(self.width * factor), round(self.height * factor), self.dist, self.name
        )

    def every(self, step: int) -> "Camera":
        """The camera of every ``step``-th pixel of this one in both directions: its pixel
        (x, y) is pixel (step·x, step·y) here, the same ray (a progressive render's
        coarse level, ``image[::step, ::step]``); size ceil(W / step) x ceil(H / step)."""
        K = self.K.copy()
        K[:2] /= step
        return Camera(
            K, self.R, self.t, -(-self.width // step), -(-self.height // step), self.dist, self.name
        )

    def project(self, points) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (N, 2) and depths (N,) of world points (N, 3); ignores distortion
        (images are undistorted on load)."""
        cam = np.asarray(points, dtype=np.float64) @ self.R.T + self.t
        z = cam[:, 2]
        uv = cam @ self.K.T
        with np.errstate(divide="ignore", invalid="ignore"):
            return uv[:, :2] / uv[:, 2:3], z

    def pixel_rays(self, pixels=None, dtype=torch.float32) -> tuple[torch.Tensor, torch.Tensor]:
        """World-space ray origins and unit directions through pixel centres.

        Args:
            pixels: (N, 2) pixel coordinates (x, y); None for every pixel, row-major.

        Returns:
            origins (N, 3), directions (N, 3).
        """
        if pixels is None:  # every pixel: kept for the last few cameras (a frame's rays)
            key = (self.K.tobytes(), self.R.tobytes(), self.t.tobytes(), self.width, self.height, dtype)
            if key not in _EVERY_PIXEL:
                ys, xs = np.mgrid[0 : self.height, 0 : self.width]
                _EVERY_PIXEL[key] = self.pixel_rays(np.stack([xs.ravel(), ys.ravel()], -1), dtype)
                while len(_EVERY_PIXEL) > _EVERY_PIXEL_KEPT:
                    _EVERY_PIXEL.popitem(last=False)
            _EVERY_PIXEL.move_to_end(key)
            return tuple(x.clone() for x in _EVERY_PIXEL[key])
        pix = np.asarray(pixels, dtype=np.float64)
        homo = np.concatenate([pix, np.ones((len(pix), 1))], 1)
        dirs = homo @ np.linalg.inv(self.K).T @ self.R  # (R^T d_cam)^T
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        origins = np.broadcast_to(self.center, dirs.shape)
        return torch.as_tensor(origins.copy(), dtype=dtype), torch.as_tensor(dirs, dtype=dtype)

    def distort_normalized(self, xy: np.ndarray) -> np.ndarray:
        """Apply the distortion model to normalised image coordinates (N, 2)."""
        k1, k2, p1, p2, k3 = self.dist
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return np.stack([xd, yd], -1)

    def undistort_image(self, image: np.ndarray, nearest: bool = False) -> np.ndarray:
        """Resample a distorted image (H, W[, C]) onto the ideal pinhole grid of this camera."""
        if not np.any(self.dist):
            return image
        return _undistortion_taps(self, nearest).apply(image).reshape(image.shape)

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "K": self.K.tolist(),
            "R": self.R.tolist(),
            "t": self.t.tolist(),
            "width": self.width,
            "height": self.height,
            "dist": self.dist.tolist(),
        }


#: Undistortion taps kept per calibration (K, dist, size) and filter: 13 bytes a pixel
#: (13 MB at 1024²). Computed once, a 1024² image's undistortion is then four gathers.
_UNDISTORTION_TAPS: dict[tuple, PixelTaps] = {}
_MAX_MAPS = 32
_CORNERS = ((0, 0), (1, 0), (0, 1), (1, 1))  # the bilinear taps' offsets (dx, dy)


@dataclass(frozen=True)
class PixelTaps:
    """Where sampling an (H, W[, C]) image at N float pixel positions reads, for images
    ``width`` wide: ``base`` (N,) int32 the flat pixel at the position's floor (rounded
    for nearest), ``fx``, ``fy`` (N,) float32 its fractions, ``inside`` (N,) uint8 one bit
    per tap (00, 10, 01, 11) that lies in the image. ``apply`` gathers any image of that
    size, so one set of taps serves every frame of a camera."""

    base: np.ndarray
    fx: np.ndarray
    fy: np.ndarray
    inside: np.ndarray
    width: int
    nearest: bool

    @classmethod
    def at(cls, shape: tuple, x: np.ndarray, y: np.ndarray, nearest: bool = False) -> PixelTaps:
        h, w = shape[:2]
        x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
        x0, y0 = (np.rint(x), np.rint(y)) if nearest else (np.floor(x), np.floor(y))
        x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
        fx, fy = (x - x0).astype(np.float32), (y - y0).astype(np.float32)
        inside = np.zeros(len(x0), np.uint8)
        for bit, (dx, dy) in enumerate(_CORNERS[:1] if nearest else _CORNERS):
            xi, yi = x0 + dx, y0 + dy
            inside |= (((xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)) << bit).astype(np.uint8)
        base = np.where(inside > 0, y0 * w + x0, 0).astype(np.int32)
        return cls(base, fx, fy, inside, w, nearest)

    def apply(self, image: np.ndarray) -> np.ndarray:
        """(N, C) samples of ``image`` (H, W[, C]) at the taps' positions, zero outside;
        integer images are rounded back to their type."""
        h, w = image.shape[:2]
        img = image.reshape(h * w, -1)
        if self.nearest:
            out = img[self.base]
            out[(self.inside & 1) == 0] = 0
            return out
        fx, fy = self.fx, self.fy
        weights = ((1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy)
        out = np.zeros((len(self.base), img.shape[1]), np.float32)
        for bit, ((dx, dy), wgt) in enumerate(zip(_CORNERS, weights)):
            ok = (self.inside & (1 << bit)) > 0
            # every pixel gathered (index 0 outside, weight 0): no boolean-mask copies
            index = np.where(ok, self.base + (dy * self.width + dx), 0)
            out += np.where(ok, wgt, np.float32(0))[:, None] * img[index]
        if image.dtype.kind == "f":
            return out.astype(image.dtype)
        return np.clip(out + 0.5, 0, 255).astype(image.dtype)


def _undistortion_taps(cam: Camera, nearest: bool) -> PixelTaps:
    """The taps that read, for every ideal pixel (row-major), its place in the distorted image."""
    key = (cam.K.tobytes(), cam.dist.tobytes(), cam.width, cam.height, nearest)
    if key not in _UNDISTORTION_TAPS:
        ys, xs = np.mgrid[0 : cam.height, 0 : cam.width].astype(np.float64)
        xy = np.stack(
            [(xs.ravel() - cam.K[0, 2]) / cam.K[0, 0], (ys.ravel() - cam.K[1, 2]) / cam.K[1, 1]], -1
        )
        d = cam.distort_normalized(xy)
        if len(_UNDISTORTION_TAPS) >= _MAX_MAPS:
            _UNDISTORTION_TAPS.pop(next(iter(_UNDISTORTION_TAPS)))
        src_x = (d[:, 0] * cam.K[0, 0] + cam.K[0, 2]).astype(np.float32)
        src_y = (d[:, 1] * cam.K[1, 1] + cam.K[1, 2]).astype(np.float32)
        _UNDISTORTION_TAPS[key] = PixelTaps.at((cam.height, cam.width), src_x, src_y, nearest)
    return _UNDISTORTION_TAPS[key]


def sample_image(image: np.ndarray, x: np.ndarray, y: np.ndarray, nearest: bool = False) -> np.ndarray:
    """Sample an image (H, W[, C]) at float pixel positions (N,), zero outside."""
    return PixelTaps.at(image.shape, x, y, nearest).apply(image)


def look_at(eye, target, up=(0.0, 1.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV extrinsics (R (3, 3), t (3,)) of a camera at ``eye`` looking at ``target``."""
    eye, target, up = (np.asarray(a, dtype=np.float64) for a in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(-up, z)  # OpenCV: x = y × z with y pointing down
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("look_at: viewing direction is parallel to up")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ eye
