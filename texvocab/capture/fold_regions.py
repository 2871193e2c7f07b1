"""Fold regions of a synthetic capture: per novel frame and view, the pixels whose truth
changes with pose, i.e. where the true image and the same view rendered with the
clothing's rest-pose folds (same body, same camera) differ by more than
:data:`FOLD_THRESHOLD` in some channel.

``texvocab synth`` writes them to ``CAPTURE/fold_regions.npz`` (:data:`FOLD_REGIONS_FILE`);
no capture reader loads them, so they never reach a model; ``texvocab eval`` scores
renders on them (:mod:`texvocab.metrics.fold_region`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: A pixel belongs to the fold region when truth and rest-fold rendering differ by more
#: than this (max over RGB, images in [0, 1]; 8 / 255).
FOLD_THRESHOLD = 8.0 / 255.0
FOLD_REGIONS_FILE = "fold_regions.npz"


def fold_region(truth: np.ndarray, rest_folds: np.ndarray, threshold: float = FOLD_THRESHOLD) -> np.ndarray:
    """(H, W) bool: where ``truth`` (H, W, 3) and ``rest_folds`` (H, W, 3) differ by more
    than ``threshold`` in some channel."""
    t, r = np.asarray(truth, np.float64), np.asarray(rest_folds, np.float64)
    return np.abs(t - r).max(axis=-1) > threshold


class FoldRegions:
    """The fold regions a synthetic capture stores: ``region(frame, view)`` -> (H, W) bool
    or None (frame or view not stored)."""

    def __init__(self, frames: np.ndarray, views: np.ndarray, masks: np.ndarray):
        self._index = {(int(t), int(v)): (i, j) for i, t in enumerate(frames) for j, v in enumerate(views)}
        self.masks = masks  # (n_frames, n_views, H, W) bool

    def region(self, frame: int, view: int) -> np.ndarray | None:
        ij = self._index.get((int(frame), int(view)))
        return None if ij is None else self.masks[ij]

    @classmethod
    def load(cls, root: str | Path) -> FoldRegions | None:
        """The regions stored in capture folder ``root``; None when there are none."""
        path = Path(root) / FOLD_REGIONS_FILE
        if not path.is_file():
            return None
        with np.load(path) as z:
            shape = tuple(int(s) for s in z["shape"])
            masks = np.unpackbits(z["bits"], count=int(np.prod(shape))).reshape(shape).astype(bool)
            return cls(z["frames"], z["views"], masks)

    @staticmethod
    def save(root: str | Path, frames, views, masks: np.ndarray) -> Path:
        """Write regions (n_frames, n_views, H, W) bool of ``frames`` x ``views``."""
        path = Path(root) / FOLD_REGIONS_FILE
        masks = np.asarray(masks, bool)
        np.savez_compressed(
            path,
            frames=np.asarray(frames, np.int64),
            views=np.asarray(views, np.int64),
            shape=np.asarray(masks.shape, np.int64),
            bits=np.packbits(masks.reshape(-1)),
        )
        return path
