"""Copies of a ZJU-layout capture that are another capture: a camera moved, a frame fewer."""

import shutil
from pathlib import Path

import numpy as np


def _edit_annots(root: Path, change) -> None:
    annots = np.load(root / "annots.npy", allow_pickle=True).item()
    change(annots)
    np.save(root / "annots.npy", annots, allow_pickle=True)


def moved_camera(root: Path) -> None:
    """View 0 of the capture in ``root`` moved by 1 cm along its x axis (a recalibration)."""

    def move(annots):
        annots["cams"]["T"] = [np.asarray(t, dtype=np.float64).copy() for t in annots["cams"]["T"]]
        annots["cams"]["T"][0].reshape(-1)[0] += 10.0  # millimetres, as ZJU-MoCap stores T

    _edit_annots(Path(root), move)


def fewer_frames(root: Path) -> None:
    """The capture in ``root`` without its last frame."""
    _edit_annots(Path(root), lambda annots: annots.update(ims=annots["ims"][:-1]))


def capture_copy(src: Path, dst: Path, change) -> Path:
    """``src`` copied to ``dst`` without its texture-map cache, then ``change(dst)``."""
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns("texvocab_cache"))
    change(dst)
    return dst
