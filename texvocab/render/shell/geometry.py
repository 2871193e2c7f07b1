"""The thin shell {x : |d(x)| <= δ} around the posed body, where d is the distance to the
posed mesh: which rays hit it, where along them, and which samples lie inside it.

Everything here is geometry only (no field evaluations) and conservative by
construction: a ray that passes within δ of the surface is never culled and no point
within δ of the surface is ever skipped. Two structures, built once per posed mesh by
:meth:`ShellGeometry.build`:

* **Bounding balls** for culling and [near, far]. The surface is sampled densely (every
  surface point lies within ``r0`` of a sample); the samples are binned into cubes of side
  δ, and each bin becomes a ball at the mean of its samples with radius
  ``δ + r0 + (farthest sample of the bin)``. Any x with d(x) <= δ lies in some ball
  (triangle inequality), so the shell is inside the union of balls.
  :meth:`ShellGeometry.image_bounds` splats the balls into the image (exact ray-sphere
  intersection for every pixel inside each ball's projected bounding box), giving per
  pixel ``hit`` and the ray-distance interval [near, far] (``t`` along the unit ray, not
  camera z). Balls straddling the camera plane (camera inside or next to the shell) are
  tested against every pixel; near clamps at 0.
* **Occupancy grid** for sample placement. A path step of length s = h/2 is kept if its
  midpoint's voxel (side h, default 1 cm) is marked; a voxel is marked if its centre c
  has d(c) <= δ + s/2 + h√3/2, so every point within δ + s/2 of the surface lies in a
  marked voxel, and every shell point is within s/2 of a kept step's midpoint. d(c) is
  bracketed by a Euclidean distance transform of the voxels holding surface samples
  (error at most h√3/2 + r0); the voxels it cannot decide get the exact distance of
  their centre (:class:`~texvocab.geometry.surface.SurfaceIndex`), or are all marked when
  ``exact=False``. :func:`~texvocab.render.shell.path.trace_path` walks each ray from near to
  far and returns its *path*: the kept steps, gaps removed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from texvocab.geometry.surface import SurfaceIndex
from texvocab.render.kernels.splat import splat_balls, stamp_distance
from texvocab.render.shell.balls import surface_balls, surface_samples


@dataclass
class ShellBounds:
    """Per pixel of one camera: ``hit`` (H, W) bool, ``near``/``far`` (H, W) float32 ray
    distances (metres along the unit ray from the camera centre), zero where not hit."""

    hit: torch.Tensor
    near: torch.Tensor
    far: torch.Tensor


@dataclass
class ShellGeometry:
    """Bounding balls and occupancy grid of the δ-shell of one posed mesh (see module doc).

    width: δ (metres). voxel: h. step: s = h/2, the path resolution of :func:`trace_path`.
    centers: (B, 3) float64 ball centres, radii: (B,) float64.
    origin: (3,) grid corner (world); occupied: (X, Y, Z) bool voxels.
    """

    width: float
    voxel: float
    step: float
    centers: np.ndarray
    radii: np.ndarray
    origin: np.ndarray | None
    occupied: torch.Tensor | None

    @property
    def has_grid(self) -> bool:
        """False for a shell built with ``grid=False`` (bounding balls only)."""
        return self.occupied is not None

    @classmethod
    def build(
        cls,
        vertices,
        faces,
        width: float = 0.04,
        voxel: float = 0.01,
        exact: bool = True,
        index: SurfaceIndex | None = None,
        grid: bool = True,
    ) -> "ShellGeometry":
        """From posed vertices (V, 3) and faces (F, 3) (tensors or arrays), shell width δ
        and voxel size h (smaller is tighter but costs a bigger grid).

        ``exact``: voxels the distance transform cannot decide get the exact distance of
        their centre (``index``, a :class:`SurfaceIndex` of this mesh, is built if not
        given); False keeps them all (faster build, looser shell). ``grid=False`` builds
        the bounding balls only (:meth:`image_bounds`, :meth:`ray_bounds`; about half
        the time), not the occupancy grid the shell marcher places samples with."""
        v = np.asarray(torch.as_tensor(vertices).detach().cpu(), dtype=np.float64)
        f = np.asarray(torch.as_tensor(faces).cpu(), dtype=np.int64)
        h = float(voxel)
        centers, radii, r0 = surface_balls(v, f, h / 2, width)
        if not grid:
            return cls(float(width), h, h / 2, centers, radii, None, None)
        samples, _ = surface_samples(v, f, h / 2)
        origin, occupied = _occupancy(v, f, samples, r0, width, h, exact, index)
        return cls(float(width), h, h / 2, centers, radii, origin, torch.from_numpy(occupied))

    def contains(self, points: torch.Tensor) -> torch.Tensor:
        """(N,) bool: points (N, 3) whose voxel is occupied (True for every point within
        δ + step/2 of the surface; also for some points a little farther)."""
        if self.occupied is None:
            raise ValueError("this ShellGeometry was built without its grid (grid=False)")
        origin = torch.as_tensor(self.origin, dtype=points.dtype)
        ijk = torch.floor((points - origin) / self.voxel).long()
        shape = torch.tensor(self.occupied.shape)
        inside = ((ijk >= 0) & (ijk < shape)).all(1)
        flat = (ijk[:, 0] * shape[1] + ijk[:, 1]) * shape[2] + ijk[:, 2]
        out = torch.zeros(len(points), dtype=torch.bool)
        out[inside] = self.occupied.view(-1)[flat[inside]]
        return out

    def ray_bounds(
        self, origins: torch.Tensor, dirs: torch.Tensor, chunk: int = 1024
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Brute force over all balls for arbitrary rays (training batches; the reference
        for :meth:`image_bounds`). origins, dirs (R, 3), dirs unit.

        Returns hit (R,) bool, near (R,), far (R,) float32 ray distances (0 if no hit).
        """
        c = torch.from_numpy(self.centers)
        r2 = torch.from_numpy(self.radii) ** 2
        near, far = [], []
        for s in range(0, len(origins), chunk):
            rel = c[None] - origins[s : s + chunk, None].double()
            m = (rel * dirs[s : s + chunk, None].double()).sum(-1)
            h2 = r2 - ((rel * rel).sum(-1) - m * m)
            root = h2.clamp(min=0).sqrt()
            ok = (h2 >= 0) & (m + root > 0)
            near.append(torch.where(ok, m - root, torch.inf).amin(1))
            far.append(torch.where(ok, m + root, -torch.inf).amax(1))
        return _finish(torch.cat(near), torch.cat(far))

    def image_bounds(self, camera) -> ShellBounds:
        """Per-pixel hit and [near, far] for a :class:`~texvocab.capture.Camera` (pixel
        centres, as :meth:`Camera.pixel_rays`), by splatting the bounding balls."""
        H, W = camera.height, camera.width
        p = self.centers @ camera.R.T + camera.t  # (B, 3) camera frame
        rho = self.radii
        ys, xs = np.mgrid[0:H, 0:W]
        d = np.stack([xs.ravel(), ys.ravel(), np.ones(H * W)], 1) @ np.linalg.inv(camera.K).T
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        near = np.full(H * W, np.inf)
        far = np.full(H * W, -np.inf)
        front = p[:, 2] > rho * (1 + 1e-9)
        boxes = _pixel_boxes(p[front], rho[front], camera.K, W, H)
        # rare: balls straddling the camera plane (camera inside or next to the shell) are
        # tested against every pixel
        plane = np.flatnonzero(~front & (p[:, 2] >= -rho))
        full = [np.full(len(plane), v, np.int64) for v in (0, W - 1, 0, H - 1)]
        balls = np.concatenate([np.flatnonzero(front), plane])
        splat_balls(
            np.ascontiguousarray(p[balls]),
            np.ascontiguousarray(rho[balls]),
            *(np.concatenate([a, b]) for a, b in zip(boxes, full, strict=True)),
            np.ascontiguousarray(d),
            W,
            near,
            far,
        )
        # as _finish, in numpy: a few single-threaded passes (torch's OpenMP threads would
        # each have to wake for them)
        near = np.maximum(near, 0.0)
        hit = far > near
        n = np.where(hit, near, 0.0).astype(np.float32)
        f = np.where(hit, far, 0.0).astype(np.float32)
        return ShellBounds(
            torch.from_numpy(hit).view(H, W), torch.from_numpy(n).view(H, W), torch.from_numpy(f).view(H, W)
        )


def _occupancy(
    v: np.ndarray,
    f: np.ndarray,
    samples: np.ndarray,
    r0: float,
    width: float,
    h: float,
    exact: bool,
    index: SurfaceIndex | None,
) -> tuple[np.ndarray, np.ndarray]:
    """The occupancy grid of :class:`ShellGeometry` (module doc): its corner (3,) and the
    (X, Y, Z) bool voxels of side h."""
    step = h / 2
    reach = width + step / 2 + h * np.sqrt(3) / 2  # centre distance that must be kept
    slack = h * np.sqrt(3) / 2
    origin = v.min(0) - reach - slack - r0 - 2 * h
    shape = np.ceil((v.max(0) + reach + slack + r0 + 2 * h - origin) / h).astype(np.int64)
    ijk = np.floor((samples - origin) / h).astype(np.int64)
    cells = np.unique((ijk[:, 0] * shape[1] + ijk[:, 1]) * shape[2] + ijk[:, 2])
    cells = np.column_stack(np.unravel_index(cells, tuple(shape)))
    # distance from each voxel centre to the nearest voxel holding a sample, up to the
    # farthest one used below: d(c) lies within ±(slack + r0) of it
    near_voxel = np.sqrt(_bounded_edt2(cells, tuple(shape), (reach + slack + r0) / h)) * h
    occupied = near_voxel <= reach - slack
    unsure = np.argwhere(~occupied & (near_voxel <= reach + slack + r0))
    if exact and len(unsure):
        index = index or SurfaceIndex(v, f)
        dist = np.asarray(index.project(origin + (unsure + 0.5) * h, max_distance=reach).distance)
        keep = unsure[np.abs(dist) <= reach]
    else:
        keep = unsure
    occupied[keep[:, 0], keep[:, 1], keep[:, 2]] = True
    return origin, occupied


def _bounded_edt2(cells: np.ndarray, shape: tuple[int, int, int], radius: float) -> np.ndarray:
    """(X, Y, Z) squared distance (in voxels) from each voxel centre to the nearest of
    ``cells`` (U, 3), exact up to ``radius`` voxels and inf beyond."""
    r = int(np.floor(radius + 1e-9))
    grid = np.stack(np.meshgrid(*(np.arange(-r, r + 1),) * 3, indexing="ij"), -1).reshape(-1, 3)
    d2 = (grid**2).sum(1)
    keep = d2 <= radius * radius * (1 + 1e-9)
    dist2 = np.full(shape, np.inf)
    stamp_distance(
        np.ascontiguousarray(cells), np.ascontiguousarray(grid[keep]), d2[keep].astype(np.float64), dist2
    )
    return dist2


def shell_bounds(vertices, faces, camera, width: float = 0.04) -> ShellBounds:
    """Per-pixel hit and [near, far] ray distances of the δ-shell of a posed mesh seen by
    ``camera`` (builds a :class:`ShellGeometry`; keep one to reuse it across views)."""
    return ShellGeometry.build(vertices, faces, width).image_bounds(camera)


def _finish(near: torch.Tensor, far: torch.Tensor):
    """(hit, near clamped at 0, far) float32, zeros where not hit."""
    hit = far > near.clamp(min=0)
    zero = torch.zeros_like(near)
    return (hit, torch.where(hit, near.clamp(min=0), zero).float(), torch.where(hit, far, zero).float())


def _pixel_boxes(p: np.ndarray, rho: np.ndarray, K: np.ndarray, width: int, height: int):
    """(x0, x1, y0, y1) int64 (B,): the pixel centres inside each ball's projected
    bounding box, clipped to the image (empty when x1 < x0 or y1 < y0); balls p (B, 3) in
    the camera frame, strictly in front (z > rho)."""
    lo_x, hi_x = _tangent_range(p[:, 0], p[:, 2], rho)
    lo_y, hi_y = _tangent_range(p[:, 1], p[:, 2], rho)
    skew = K[0, 1]
    sk_lo, sk_hi = np.minimum(skew * lo_y, skew * hi_y), np.maximum(skew * lo_y, skew * hi_y)
    x0 = np.ceil(K[0, 0] * lo_x + sk_lo + K[0, 2] - 1e-6)
    x1 = np.floor(K[0, 0] * hi_x + sk_hi + K[0, 2] + 1e-6)
    y0 = np.ceil(K[1, 1] * lo_y + K[1, 2] - 1e-6)
    y1 = np.floor(K[1, 1] * hi_y + K[1, 2] + 1e-6)
    x0, y0 = np.clip(x0, 0, width), np.clip(y0, 0, height)
    x1, y1 = np.clip(x1, -1, width - 1), np.clip(y1, -1, height - 1)
    return tuple(a.astype(np.int64) for a in (x0, x1, y0, y1))


def _tangent_range(a: np.ndarray, z: np.ndarray, rho: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Range of a/z over balls (centre (a, z) in a plane through the camera, radius rho,
    z > rho): tan(atan2(a, z) -/+ asin(rho / |(a, z)|))."""
    angle = np.arctan2(a, z)
    half = np.arcsin(np.clip(rho / np.hypot(a, z), 0, 1))
    return np.tan(angle - half), np.tan(angle + half)
