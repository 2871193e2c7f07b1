"""How well a posed body covers a capture's masks: silhouette IoU per frame, the joints'
reprojection offsets, and how close each mask pixel's camera ray passes to the posed
surface (the shell width real data needs).

Masks are in the camera's ideal pinhole image (undistorted, as
:meth:`texvocab.capture.Capture.mask` returns them); the silhouette is rasterised with
:func:`texvocab.geometry.raster.rasterize_mesh`, pixel centres at integer coordinates.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import torch

from texvocab.capture.camera import Camera
from texvocab.geometry.raster import rasterize_mesh
from texvocab.geometry.surface import SurfaceIndex


@dataclass
class SilhouetteFit:
    """Per frame (T,): ``iou`` = |S ∩ M| / |S ∪ M|; ``precision`` = |S ∩ M| / |S| (the
    share of the body's silhouette S inside the mask M); ``recall`` = |S ∩ M| / |M|."""

    iou: np.ndarray
    precision: np.ndarray
    recall: np.ndarray


def body_silhouette(vertices, faces, camera: Camera) -> np.ndarray:
    """(H, W) bool: pixels whose centre a posed mesh (vertices (V, 3), faces (F, 3))
    covers in ``camera``."""
    return rasterize_mesh(torch.as_tensor(vertices), torch.as_tensor(faces), camera).mask.numpy()


def overlap(silhouette: np.ndarray, mask: np.ndarray) -> tuple[float, float, float]:
    """(IoU, precision, recall) of a silhouette against a mask, both (H, W) bool; 1.0 for
    a ratio whose denominator is empty (nothing to miss)."""
    inter = float(np.logical_and(silhouette, mask).sum())

    def ratio(den: float) -> float:
        return inter / den if den else 1.0

    return (
        ratio(float(np.logical_or(silhouette, mask).sum())),
        ratio(float(silhouette.sum())),
        ratio(float(mask.sum())),
    )


def posed_vertices(body, poses, trans, betas=None) -> Iterable[torch.Tensor]:
    """(V, 3) posed vertices of each frame of poses (T, J, 3) and trans (T, 3), one frame
    at a time; betas (1, S) or None."""
    for pose, tr in zip(torch.as_tensor(np.asarray(poses)), torch.as_tensor(np.asarray(trans))):
        yield body.forward(pose[None], tr[None], betas).vertices[0]


def silhouette_fit(
    body, poses, trans, camera: Camera, masks: Iterable[np.ndarray], betas=None
) -> SilhouetteFit:
    """IoU, precision and recall of the posed body's silhouette against each frame's mask.

    Args:
        body: a :class:`~texvocab.body.BodyModel`.
        poses: (T, J, 3) axis-angle, root orientation at joint 0; trans: (T, 3).
        camera: the view the masks were taken from.
        masks: T masks (H, W) bool in frame order (any iterable: a generator keeps one
            frame in memory).
        betas: (1, S) shape coefficients or None.
    """
    rows = []
    faces = body.faces
    for verts, mask in zip(posed_vertices(body, poses, trans, betas), masks, strict=True):
        if mask.shape != (camera.height, camera.width):
            raise ValueError(
                f"mask is {mask.shape[1]}x{mask.shape[0]}, camera "
                f"{camera.name!r} is {camera.width}x{camera.height}"
            )
        rows.append(overlap(body_silhouette(verts, faces, camera), mask))
    iou, precision, recall = (np.asarray(c, dtype=np.float64) for c in zip(*rows))
    return SilhouetteFit(iou, precision, recall)


def reprojection_offsets(camera: Camera, joints, reference) -> np.ndarray:
    """(..., J) pixel distance between the projections of world joints (..., J, 3) and
    of reference joints (..., J, 3)."""
    a, b = (np.asarray(x, dtype=np.float64) for x in (joints, reference))
    pa, _ = camera.project(a.reshape(-1, 3))
    pb, _ = camera.project(b.reshape(-1, 3))
    return np.linalg.norm(pa - pb, axis=1).reshape(a.shape[:-1])


def _box_span(
    origins: np.ndarray, dirs: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Entry and exit ray parameters (N,) of rays (N, 3) through an axis-aligned box
    (slab test); exit < entry for a ray that misses it."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = (lo - origins) / dirs, (hi - origins) / dirs
    near = np.nan_to_num(np.minimum(t0, t1), nan=-np.inf).max(1)
    far = np.nan_to_num(np.maximum(t0, t1), nan=np.inf).min(1)
    return np.maximum(near, 0.0), far


def ray_surface_distances(
    vertices,
    faces,
    camera: Camera,
    pixels,
    max_distance: float = 0.1,
    step: float = 0.0025,
    silhouette: np.ndarray | None = None,
) -> np.ndarray:
    """(N,) how close the camera ray through each pixel (N, 2) (x, y integers) passes to
    a posed mesh (vertices (V, 3), faces (F, 3)), metres; inf beyond ``max_distance``.

    A ray through the mesh's silhouette meets the surface (0). Other rays are sampled
    every ``step`` metres inside the mesh's bounding box grown by ``max_distance``, and
    each sample's exact closest surface point is found (:class:`SurfaceIndex`, Eq. 7's
    projection); the smallest distance over the samples over-estimates the ray's by at
    most ``step / 2`` (the distance to a surface changes no faster than the point moves).
    ``silhouette``, the mesh's (H, W) silhouette in this camera, saves rasterising it.
    """
    verts = torch.as_tensor(vertices).detach().double().numpy()
    pix = np.asarray(pixels, dtype=np.int64).reshape(-1, 2)
    if silhouette is None:
        silhouette = body_silhouette(verts, faces, camera)
    out = np.where(silhouette[pix[:, 1], pix[:, 0]], 0.0, np.inf)
    miss = np.nonzero(np.isinf(out))[0]
    out[miss] = _closest_approach(verts, faces, camera, pix[miss], max_distance, step)[0]
    return out


def _closest_approach(
    verts: np.ndarray, faces, camera: Camera, pix: np.ndarray, max_distance: float, step: float, index=None
):
    """For the rays through pixels pix (M, 2): the smallest sampled distance to the mesh
    (M,) (inf beyond ``max_distance``) and the sample where it is reached (M, 3) (NaN
    there), as :func:`ray_surface_distances` samples them; ``index``: the mesh's
    SurfaceIndex (None: built here)."""
    dist, where = np.full(len(pix), np.inf), np.full((len(pix), 3), np.nan)
    if not len(pix):
        return dist, where
    origins, dirs = (t.double().numpy() for t in camera.pixel_rays(pix))
    near, far = _box_span(origins, dirs, verts.min(0) - max_distance, verts.max(0) + max_distance)
    hit = np.nonzero(far > near)[0]
    if not len(hit):
        return dist, where
    count = int(np.ceil((far[hit] - near[hit]).max() / step)) + 1
    ts = near[hit, None] + step * np.arange(count)[None]  # (R, K); samples past the exit clamp
    ts = np.minimum(ts, far[hit, None])
    points = origins[hit, None] + ts[..., None] * dirs[hit, None]
    if index is None:
        index = SurfaceIndex(verts, np.asarray(torch.as_tensor(faces)))
    d = np.abs(index.project(points.reshape(-1, 3), max_distance=max_distance).distance).reshape(
        len(hit), count
    )
    best = d.argmin(1)
    dist[hit] = d[np.arange(len(hit)), best]
    where[hit] = points[np.arange(len(hit)), best]
    return dist, where


def ray_surface_reach(
    vertices, faces, weights, camera: Camera, pixels, max_distance: float = 0.1, step: float = 0.0025
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`ray_surface_distances` of pixels (N, 2) and the body joint each ray comes
    closest to: (distance (N,), joint (N,) long), the joint with the largest skinning
    weight (``weights`` (V, J)) at the ray's closest surface point (the face a ray through
    the silhouette hits first); -1 beyond ``max_distance``."""
    verts = torch.as_tensor(vertices).detach().double().numpy()
    f = np.asarray(torch.as_tensor(faces), np.int64)
    w = np.asarray(torch.as_tensor(weights).detach().double())
    pix = np.asarray(pixels, dtype=np.int64).reshape(-1, 2)
    raster = rasterize_mesh(torch.as_tensor(verts), torch.as_tensor(f), camera)
    face = raster.face.numpy()[pix[:, 1], pix[:, 0]]
    inside = raster.mask.numpy()[pix[:, 1], pix[:, 0]]
    dist = np.where(inside, 0.0, np.inf)
    joint = np.full(len(pix), -1, np.int64)
    joint[inside] = w[f[face[inside]]].sum(1).argmax(1)
    miss = np.nonzero(~inside)[0]
    index = SurfaceIndex(verts, f)
    d, where = _closest_approach(verts, f, camera, pix[miss], max_distance, step, index)
    dist[miss] = d
    near = np.isfinite(d)
    if near.any():
        proj = index.project(where[near], weights=w, max_distance=max_distance + step)
        joint[miss[near]] = np.where(proj.face >= 0, np.nan_to_num(proj.weights, nan=-1.0).argmax(1), -1)
    return dist, joint


def shell_coverage(
    body,
    poses,
    trans,
    camera: Camera,
    masks: Iterable[np.ndarray],
    deltas=(0.02, 0.04, 0.06, 0.08, 0.1),
    pixel_stride: int = 4,
    betas=None,
    step: float = 0.0025,
) -> np.ndarray:
    """(T, D) share of each frame's mask pixels whose camera ray passes within each of
    ``deltas`` (D,) metres of the posed body's surface: how wide a shell around the body
    must be to reach the person in the images. Mask pixels are taken on a grid of every
    ``pixel_stride``-th pixel in x and y; see :func:`ray_surface_distances` (its bias is
    at most ``step / 2``)."""
    deltas = np.asarray(deltas, dtype=np.float64)
    rows = []
    for verts, mask in zip(posed_vertices(body, poses, trans, betas), masks, strict=True):
        grid = np.zeros_like(mask, dtype=bool)
        grid[::pixel_stride, ::pixel_stride] = True
        ys, xs = np.nonzero(mask & grid)
        if not len(ys):
            rows.append(np.ones(len(deltas)))
            continue
        dist = ray_surface_distances(
            verts, body.faces, camera, np.stack([xs, ys], 1), max_distance=float(deltas.max()), step=step
        )
        rows.append((dist[:, None] <= deltas[None]).mean(0))
    return np.asarray(rows).reshape(-1, len(deltas))
