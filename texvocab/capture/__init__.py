"""Multi-view captures: cameras, the Capture container, ZJU-MoCap / THUman4.0 readers and
writers, the HumanNeRF (one camera) reader, and synthetic captures with ground truth at
any pose."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np
import torch

from texvocab.body import load_body
from texvocab.capture.camera import Camera
from texvocab.capture.capture import SYNTH_META, Capture, read_synth_meta
from texvocab.capture.humannerf import is_humannerf, read_humannerf
from texvocab.capture.subject import fit_subject_body, smplx_subject
from texvocab.capture.thuman import is_thuman, read_thuman
from texvocab.capture.zju import is_zju, read_zju
from texvocab.errors import AssetError, PoseError


def detect_layout(path: str | Path) -> str:
    """``zju``, ``thuman`` or ``humannerf`` for a capture folder; raises AssetError naming
    what is missing."""
    root = Path(path)
    if not root.is_dir():
        raise AssetError(f"capture folder not found: {root}")
    if is_zju(root):
        return "zju"
    if is_thuman(root):
        return "thuman"
    if is_humannerf(root):
        return "humannerf"
    raise AssetError(
        f"{root}: not a capture folder: expected annots.npy (ZJU-MoCap), "
        "calibration.json (THUman4.0) or cameras.pkl + mesh_infos.pkl (HumanNeRF); "
        "see assets_spec/captures.md"
    )


READERS = {"zju": read_zju, "thuman": read_thuman, "humannerf": read_humannerf}
MAX_AUTO_SIDE = 768  # the automatic image scale halves images until no side exceeds this


def auto_image_scale(cameras) -> float:
    """The image scale a capture trains and evaluates at by default: 1, halved until every
    view's longest side is at most ``MAX_AUTO_SIDE`` px (a 1024² capture: 0.5, i.e. 512²;
    the synthetic captures' 256²: 1). Power-of-two factors keep the area average exact."""
    side, scale = max(max(c.width, c.height) for c in cameras), 1.0
    while side * scale > MAX_AUTO_SIDE:
        scale *= 0.5
    return scale


def open(
    path: str | Path,
    body=None,
    num_train: int | None = None,  # noqa: A001
    image_scale: float | None = None,
    fit_body: bool = True,
    smplx: str | Path | None = None,
) -> Capture:
    """Open a capture folder, choosing the reader from its layout.

    Args:
        path: a ZJU-MoCap, THUman4.0 or HumanNeRF-style folder (or one written by
            ``texvocab synth``).
        body: the body model its poses drive; default: the embedded default body.
        num_train: number of leading training frames; default: the synthetic capture's
            recorded split, else 70 % of the frames (80 % with one camera: its last
            frames are the held-out set).
        fit_body: fit the body to the subject's rest joints when the capture gives them
            (:func:`~texvocab.capture.subject.fit_subject_body`).
        smplx: the user's SMPL-X model file, for a capture whose fits are SMPL-X
            (THUman4.0): the body is fitted to its betas' rest joints; default
            ``$TEXVOCAB_SMPLX`` (none: the body keeps its shape, one log line says so).
        image_scale: resize images, masks and cameras by this factor on load
            (:meth:`Capture.scaled`); default :func:`auto_image_scale` (1024² -> 512²).
    """
    root = Path(path)
    layout = detect_layout(root)
    meta = read_synth_meta(root)
    if num_train is None and meta is not None:  # the generator's split
        num_train = meta.get("num_train")
        if num_train is not None and (type(num_train) is not int or num_train < 0):
            raise AssetError(f"{root / SYNTH_META}: num_train={num_train!r}; expected an integer >= 0")
    body = body if body is not None else load_body(None)
    cap = READERS[layout](root, body, num_train)
    try:  # finite and within the stated bounds (texvocab.body.model), before any work
        body.check_pose(torch.as_tensor(np.asarray(cap.poses)), torch.as_tensor(np.asarray(cap.trans)))
    except PoseError as e:
        raise AssetError(f"{root}: its SMPL parameters: {e}") from None
    if fit_body:
        cap = fit_subject_body(smplx_subject(cap, smplx or os.environ.get("TEXVOCAB_SMPLX") or None))
    if meta is None:  # a real capture: its background is not the avatar's
        cap = dataclasses.replace(cap, masked=True)
    scale = auto_image_scale(cap.cameras) if image_scale is None else float(image_scale)
    return cap if scale == 1.0 else cap.scaled(scale)


__all__ = ["Camera", "Capture", "auto_image_scale", "detect_layout", "open"]
