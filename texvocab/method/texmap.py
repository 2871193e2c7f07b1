"""Texture maps U_t (Sec. 3.2, Eq. 2): every training view back-projected onto the posed
body and gathered in the body's UV domain, averaged over views.

Eq. 2 pairs each foreground pixel with the surface point (face f*, barycentrics u*, v*)
that projects onto it. We rasterise the posed mesh in each view (face id + depth per
pixel: the depth test means occluded surface receives nothing) and pair texels with
pixels from the texel side: each covered texel is a surface point (its face and
barycentrics are fixed by the UV layout), projected into the view; it takes the view's
colour when the rasteriser says that pixel sees this very surface point (depth within
``depth_tol``) and the pixel is foreground. This is Eq. 2's pixel↔surface pairing with
bilinear resampling, and leaves no holes when the texture is finer than the image.

Eq. 2 averages the views that see a texel with equal weight (``view_weighting="mean"``).
A view seeing the surface at a grazing angle samples it blurred and stretched;
``"cosine"`` weights each view by the cosine between the surface normal and the ray to
the camera instead, so head-on views dominate.

Uncovered texels (no view saw them) keep coverage 0; their colour is copied from the
nearest covered texel so the CNN sees no artificial black seams. Both the colour and the
coverage are stored, so later stages can weight or mask by coverage.
"""

from __future__ import annotations

import logging
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from scipy import ndimage
from tqdm import tqdm

from texvocab.capture.cache_folder import capture_cache
from texvocab.capture.camera import sample_image
from texvocab.capture.frame_digest import frame_digest
from texvocab.geometry.raster import rasterize_mesh
from texvocab.geometry.uv import texel_map
from texvocab.io.full_disk import disk_full_error, is_disk_full
from texvocab.io.images import atomic_write_bytes
from texvocab.io.outputs import check_output

log = logging.getLogger("texvocab")

VIEW_WEIGHTINGS = ("mean", "cosine")


@dataclass
class TexmapSettings:
    """``size``: texture side in texels; ``views``: the camera views back-projected (the
    training views: held-out views never enter a texture map; None: every view, for
    tests and tools only); ``min_cos``: skip views seeing a texel at a more grazing angle
    than this (cosine between surface normal and view ray); ``depth_tol``: metres a texel
    may lie behind the rasterised surface and still count as visible; ``view_weighting``:
    ``mean`` (Eq. 2) or ``cosine`` (module docstring)."""

    size: int = 256
    views: tuple[int, ...] | None = None
    min_cos: float = 0.15
    depth_tol: float = 0.01
    view_weighting: str = "mean"


def _vertex_normals(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    tri = verts[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    vn = np.zeros_like(verts)
    for k in range(3):
        np.add.at(vn, faces[:, k], fn)
    return vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-12)


def build_texture_map(
    capture, frame: int, settings: TexmapSettings | None = None, views: list[int] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """U_t of one frame from ``views`` (default ``settings.views``; None there: all).

    Returns:
        texture (S, S, 3) float32 in [0, 1] (uncovered texels filled from the nearest
        covered one), coverage (S, S) float32: number of views that saw each texel.
    """
    s = settings or TexmapSettings()
    body = capture.body
    tmap = texel_map(body, s.size)
    faces = body.faces.numpy()
    verts = capture.posed_body(frame).vertices[0].double().numpy()
    points = tmap.points(verts, faces)
    normals = tmap.interpolate(_vertex_normals(verts, faces), faces)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    acc = np.zeros((len(points), 3))
    count = np.zeros(len(points))
    wsum = np.zeros(len(points))
    views = views if views is not None else settings_views(s, capture)
    for v in views:
        cam = capture.cameras[v]
        pix, z = cam.project(points)
        to_cam = cam.center - points
        cos = np.einsum("nc,nc->n", normals, to_cam) / np.linalg.norm(to_cam, axis=1)
        raster = rasterize_mesh(torch.as_tensor(verts), body.faces, cam)
        zbuf = raster.depth.numpy()
        xi, yi = np.rint(pix[:, 0]).astype(int), np.rint(pix[:, 1]).astype(int)
        inside = (xi >= 0) & (xi < cam.width) & (yi >= 0) & (yi < cam.height) & (z > 0)
        ok = inside & (cos > s.min_cos)
        ok[ok] &= z[ok] <= zbuf[yi[ok], xi[ok]] + s.depth_tol  # depth test: occluded -> nothing
        mask = capture.mask(v, frame)
        ok[ok] &= mask[yi[ok], xi[ok]]  # foreground pixels only
        if not ok.any():
            continue
        # texels whose nearest pixel is inside may sit up to half a pixel past the outer
        # pixel centres; clamp there so bilinear sampling never blends in the zero outside
        x = np.clip(pix[ok, 0], 0, cam.width - 1)
        y = np.clip(pix[ok, 1], 0, cam.height - 1)
        weight = cos[ok] if s.view_weighting == "cosine" else np.ones(int(ok.sum()))
        acc[ok] += weight[:, None] * sample_image(capture.image(v, frame), x, y)
        wsum[ok] += weight
        count[ok] += 1
    color = acc / np.where(wsum > 0, wsum, 1.0)[:, None]
    if (count > 0).any():
        # unseen texels take the nearest seen texel's colour (in UV space)
        seen = np.zeros((s.size, s.size), bool)
        seen[tmap.covered] = count > 0
        img = tmap.to_image(color, fill=False)
        _, nearest = ndimage.distance_transform_edt(~seen, return_indices=True)
        texture = img[nearest[0], nearest[1]]
    else:
        texture = np.zeros((s.size, s.size, 3))
    return texture.astype(np.float32), tmap.to_image(count.astype(np.float32), fill=False)


def settings_views(settings: TexmapSettings, capture) -> list[int]:
    """The views a texture map is built from (every view when ``settings.views`` is None)."""
    return list(range(capture.num_views)) if settings.views is None else list(settings.views)


def cache_dir(capture, settings: TexmapSettings) -> Path:
    """Where every command keeps and finds the texture maps of a capture, under its cache
    folder (:func:`~texvocab.capture.cache_folder.capture_cache`: inside the capture, or
    the user's cache folder when the capture is read-only); keyed by texture
    size and by the set of views back-projected, so maps built from other views (a cache
    from before held-out views were excluded, or another train/eval split) are never
    reused; and by the image scale and the body fit (``capture.meta["body_fit"]``) when
    they are not the defaults, so maps of another body or resolution are never reused."""
    views = "-".join(str(v) for v in settings_views(settings, capture))
    weighting = "" if settings.view_weighting == "mean" else f"_{settings.view_weighting}"
    scale = getattr(capture, "image_scale", 1.0)
    scaled = "" if scale == 1.0 else f"_x{scale:g}"
    fit = capture.meta.get("body_fit") if isinstance(getattr(capture, "meta", None), dict) else None
    body = f"_body-{fit}" if fit else ""
    return capture_cache(capture.root) / f"texmaps_{settings.size}_views_{views}{weighting}{scaled}{body}"


def texture_map_path(capture, frame: int, settings: TexmapSettings) -> Path:
    return cache_dir(capture, settings) / f"frame_{capture.frame_ids[frame]:06d}.npz"


def _cached(path: Path, size: int, digest: bytes) -> str:
    """``"ok"`` when a cached texture map is there, sound and built from the inputs
    ``digest`` names (:func:`~texvocab.capture.frame_digest.frame_digest`); ``"missing"``;
    ``"damaged"`` (a truncated or foreign file in texvocab's own cache: logged); ``"stale"``
    (built from other images, masks, calibration or pose, or before the files recorded
    their inputs). Anything but "ok" is rebuilt, never an error."""
    if not path.is_file():
        return "missing"
    try:
        with np.load(path, allow_pickle=False) as npz:
            ok = npz["texture"].shape == (size, size, 3) and npz["coverage"].shape == (size, size)
            stored = npz["inputs"].tobytes() if "inputs" in npz.files else None
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        ok, stored = False, None
    if not ok:
        log.warning("%s: damaged texture-map cache file, rebuilding it", path)
        return "damaged"
    return "ok" if stored == digest else "stale"


COVERAGE_FLOOR = 0.10  # a frame whose views saw less of the body than this is suspect


def seen_texel_share(coverage: np.ndarray, body) -> np.ndarray:
    """(T,) the share of the body's texels (those inside the UV layout) that some view saw,
    per frame, from coverage maps (T, S, S). One camera sees about a third; a broken
    calibration or mask sees almost nothing."""
    coverage = np.asarray(coverage)
    covered = texel_map(body, coverage.shape[1]).covered
    return (coverage[:, covered] > 0).mean(1)


def coverage_note(share: np.ndarray, frame_ids, floor: float = COVERAGE_FLOOR) -> tuple[str, str | None]:
    """One summary line of the per-frame ``share`` (:func:`seen_texel_share`) and a warning
    line naming the frames below ``floor`` (None when there are none)."""
    share = np.asarray(share, np.float64)
    worst = int(share.argmin())
    line = (
        f"coverage: {100 * np.median(share):.0f} % of the body's texels seen per frame "
        f"(median over {len(share)}; lowest {100 * share[worst]:.0f} %, frame {frame_ids[worst]})"
    )
    low = np.nonzero(share < floor)[0]
    if not len(low):
        return line, None
    names = ", ".join(str(frame_ids[i]) for i in low[:8]) + (", ..." if len(low) > 8 else "")
    return line, (
        f"{len(low)} of {len(share)} texture maps saw under {100 * floor:.0f} % of the body's "
        f"texels (frames {names}): check those frames' masks and the cameras' calibration"
    )


def load_texture_map(path: Path) -> tuple[np.ndarray, np.ndarray]:
    with np.load(path, allow_pickle=False) as npz:
        return npz["texture"].astype(np.float32) / 255.0, npz["coverage"].astype(np.float32)


def prepare_texture_maps(
    capture, settings: TexmapSettings | None = None, frames=None, progress: bool = True
) -> list[Path]:
    """Build and cache U_t for every training frame; resumable (existing files built from
    the same inputs are kept; each file stores its inputs' digest).

    Returns the cache file of each frame, in frame order.
    """
    s = settings or TexmapSettings()
    frames = list(capture.train_frames if frames is None else frames)
    paths = [texture_map_path(capture, t, s) for t in frames]
    views = settings_views(s, capture)
    digests = {t: frame_digest(capture, t, views) for t in frames}
    state = {t: _cached(p, s.size, digests[t]) for t, p in zip(frames, paths, strict=True)}
    todo = [(t, p) for t, p in zip(frames, paths, strict=True) if state[t] != "ok"]
    stale = sum(v == "stale" for v in state.values())
    if stale:  # a warning: the user should know the cache no longer matches the capture
        log.warning(
            "%s: %d of %d texture maps were built from other images, masks, calibration or "
            "poses (or before the cache recorded them); rebuilding them",
            cache_dir(capture, s),
            stale,
            len(frames),
        )
    if todo:  # a cache that cannot be written is one error line, before any map is built
        check_output(cache_dir(capture, s), "folder", flag="texture-map cache")
    it = todo
    if progress and todo:
        it = tqdm(todo, desc=f"texture maps {s.size}²", unit="frame")
    for t, path in it:
        texture, coverage = build_texture_map(capture, t, s)
        tex8 = (np.clip(texture, 0, 1) * 255 + 0.5).astype(np.uint8)
        inputs = np.frombuffer(digests[t], np.uint8)

        def write(tmp, tex8=tex8, coverage=coverage, inputs=inputs):
            with open(tmp, "wb") as fh:
                np.savez_compressed(fh, texture=tex8, coverage=coverage.astype(np.uint8), inputs=inputs)
                fh.flush()
                os.fsync(fh.fileno())

        try:
            atomic_write_bytes(path, write)
        except OSError as e:
            if not is_disk_full(e):
                raise
            done = sum(state[f] == "ok" for f in frames) + todo.index((t, path))
            raise disk_full_error(
                path, e, f"{done} of {len(frames)} texture maps are cached, and a new run goes on from them"
            ) from None
    return paths
