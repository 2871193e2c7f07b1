"""How well a texture map predicts an image: a map laid on a frame's posed body, seen from
that frame's camera, against the frame's own pixels (the interior: inside both the mask and
the rasterised body).

The vocabulary (Sec. 3.3) hands the field the texture maps of other frames, so the whole
texture path rests on one assumption: a body texel looks the same in frames of similar
pose. :func:`transfer_scores` measures it on a capture, texture alone and without any
training: the frame's own map (how much the back-projection keeps, an upper bound), the maps
of the frames ``d`` before it, the vocabulary's blend for the frame's pose (Eq. 5 applied
to the maps, :class:`~texvocab.method.vocab_texture.VocabTexture`) and the training frames'
mean texture (a blend that ignores the pose). ``bench/texture_transfer.py`` prints them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from scipy import ndimage

from texvocab.capture.camera import sample_image
from texvocab.geometry.raster import rasterize_mesh
from texvocab.geometry.uv import uv_to_pixel

BLUR_SIGMA = 3.0  # px: the "low frequencies" column (shading, colour) without the detail
MIN_PIXELS = 16  # fewer interior pixels than this: the frame is not scored


@dataclass
class BodyView:
    """One frame's posed body seen from one camera: ``hit`` (H, W) pixels the body covers,
    ``texel`` (N, 2) their continuous texture-image coordinates (x, y) for an S² map,
    ``interior`` (H, W) hit pixels inside the mask, ``image`` (H, W, 3) the frame's pixels."""

    hit: np.ndarray
    texel: np.ndarray
    interior: np.ndarray
    image: np.ndarray


def body_view(capture, frame: int, view: int, size: int) -> BodyView:
    """Rasterise ``frame``'s posed body in camera ``view`` with its UVs (texture size ``size``)."""
    body, cam = capture.body, capture.cameras[view]
    verts = capture.posed_body(frame).vertices[0].double()
    r = rasterize_mesh(verts, body.faces, cam)
    face = r.face.numpy()
    hit = face >= 0
    corners = body.vt.double().numpy()[body.ft.numpy()[face[hit]]]  # (N, 3, 2)
    uv = np.einsum("nk,nkc->nc", r.bary.double().numpy()[hit], corners)
    texel = uv_to_pixel(torch.as_tensor(uv), size, size).numpy()
    mask = capture.mask(view, frame) > 0.5
    return BodyView(hit, texel, hit & mask, capture.image(view, frame))


def laid_on(bv: BodyView, texture: np.ndarray) -> np.ndarray:
    """(H, W, C) ``texture`` (S, S, C) sampled at every hit pixel's UV; zero elsewhere."""
    out = np.zeros(bv.hit.shape + texture.shape[2:], np.float32)
    out[bv.hit] = sample_image(texture, bv.texel[:, 0], bv.texel[:, 1]).reshape((-1,) + texture.shape[2:])
    return out


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a - b) ** 2))
    return float("inf") if mse == 0 else -10.0 * np.log10(mse)


def interior_psnr(bv: BodyView, texture: np.ndarray, seen: np.ndarray | None = None) -> dict | None:
    """PSNR of ``texture`` laid on the body against the image on the interior pixels, as is
    and after a ``BLUR_SIGMA`` Gaussian blur of both; with ``seen`` (S, S) only where that
    map saw its texel. None when fewer than ``MIN_PIXELS`` pixels remain.

    Returns ``{"psnr", "psnr_blurred", "pixels"}``."""
    sel = bv.interior
    if seen is not None:
        sel = sel & (laid_on(bv, seen[..., None].astype(np.float32))[..., 0] > 0.99)
    if int(sel.sum()) < MIN_PIXELS:
        return None
    img = laid_on(bv, texture)
    return {
        "psnr": _psnr(img[sel], bv.image[sel]),
        "psnr_blurred": _psnr(_blur_within(img, sel)[sel], _blur_within(bv.image, sel)[sel]),
        "pixels": int(sel.sum()),
    }


def _blur_within(image: np.ndarray, sel: np.ndarray) -> np.ndarray:
    """Gaussian blur (``BLUR_SIGMA``) of ``image`` (H, W, 3) over the ``sel`` pixels only
    (normalised convolution), so that nothing outside the scored pixels leaks in."""
    w = sel.astype(np.float32)
    num = ndimage.gaussian_filter(image * w[..., None], (BLUR_SIGMA, BLUR_SIGMA, 0))
    den = ndimage.gaussian_filter(w, BLUR_SIGMA)
    return num / np.maximum(den, 1e-6)[..., None]


def summarise(rows: list[dict]) -> dict:
    """Mean, sample std and count of ``psnr`` and ``psnr_blurred`` over scored frames."""
    out: dict = {"frames": len(rows)}
    for key in ("psnr", "psnr_blurred"):
        v = np.array([r[key] for r in rows], np.float64)
        out[key] = float(v.mean()) if len(v) else None
        out[key + "_std"] = float(v.std(ddof=1)) if len(v) > 1 else None
    return out


def transfer_scores(
    capture,
    textures: np.ndarray,
    coverage: np.ndarray,
    train_frames: list[int],
    novel_frames: list[int],
    offsets: tuple[int, ...],
    blend,
    mean: np.ndarray,
    view: int = 0,
) -> dict[str, dict]:
    """The table of :mod:`texvocab.method.texture_transfer`, one row per texture source.

    Args:
        textures: (T, S, S, 3) the training frames' maps, unseen texels filled.
        coverage: (T, S, S) views that saw each texel (0: unseen).
        train_frames: training frames scored with their own map and the maps ``offsets``
            frames before them (only on texels both maps saw; offsets past frame 0 skip).
        novel_frames: frames scored with ``blend(pose)`` (S, S, 3), the vocabulary's
            texture for their pose, and with ``mean`` (S, S, 3): frames that are not keys,
            so no frame's own map enters its blend.
        view: the camera.

    Returns:
        ``{"own": summary, "d=1": …, "vocabulary blend": …, "mean texture": …}`` with the
        :func:`summarise` fields.
    """
    size = textures.shape[1]
    rows: dict[str, list[dict]] = {"own": [], **{f"d={d}": [] for d in offsets}}
    rows.update({"vocabulary blend": [], "mean texture": []})
    for t in train_frames:
        bv = body_view(capture, t, view, size)
        for name, src in [("own", t)] + [(f"d={d}", t - d) for d in offsets]:
            if src < 0:
                continue
            r = interior_psnr(bv, textures[src], (coverage[src] > 0) & (coverage[t] > 0))
            if r is not None:
                rows[name].append(r)
    for t in novel_frames:
        bv = body_view(capture, t, view, size)
        for name, tex in (("vocabulary blend", blend(capture.poses[t])), ("mean texture", mean)):
            r = interior_psnr(bv, tex)
            if r is not None:
                rows[name].append(r)
    return {name: summarise(r) for name, r in rows.items()}
