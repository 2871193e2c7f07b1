"""The body's girth from the training masks: how far the clothes stand off the body, per
joint (:mod:`texvocab.body.girth`), where the field's SDF starts.

With ``data.body_girth=masks`` a new run measures, on :data:`SAMPLE_IMAGES` training
images spread over the frames and views and reduced to at most :data:`FIT_SIZE` pixels a
side, the silhouette IoU of the posed body grown by the offsets against the masks, and
picks the per-joint offsets that maximise its mean: one offset for each joint and its
mirror twin, searched coordinate-wise in 1 cm steps from -2 cm to 2 cm inside the field's
shell (so that the residual can still move the surface outwards), starting from the best
uniform offset, for :data:`SWEEPS` sweeps. The offsets are stored in the checkpoint
(``body_girth``) and set on the field (:meth:`~texvocab.method.field.AvatarField.set_girth`)
whenever the avatar is loaded; one log line gives the fit. A body with its own shape
coefficients (the user's SMPL files and betas) is fitted the same way.
"""

from __future__ import annotations

import dataclasses
import logging

import numpy as np
from PIL import Image

from texvocab.body.girth import posed_normals, symmetric_groups, vertex_offsets
from texvocab.body.parts import JOINT_NAMES
from texvocab.capture.silhouette import body_silhouette, overlap
from texvocab.errors import TexvocabError
from texvocab.pipeline.evaluate import spread
from texvocab.pipeline.settings import Settings

log = logging.getLogger("texvocab")

SAMPLE_IMAGES = 24  #: training images the offsets are fitted on
FIT_SIZE = 256  #: the images' longest side while fitting (pixels)
LEAST, STEP, ROOM = -0.02, 0.01, 0.02  #: offsets from LEAST in STEPs to the shell less ROOM (m)
SWEEPS = 2  #: coordinate-wise passes over the joint groups
CHECKPOINT_KEY = "body_girth"


@dataclasses.dataclass(frozen=True)
class GirthFit:
    """Per-joint ``offsets`` (J,) m; mean silhouette IoU of the posed body against the
    masks of ``images`` training images before and after."""

    offsets: np.ndarray
    iou_before: float
    iou_after: float
    images: int

    def line(self) -> str:
        o = self.offsets * 100
        return (
            f"body girth: fitted to the masks of {self.images} training images, silhouette IoU "
            f"{self.iou_before:.3f} -> {self.iou_after:.3f} (offsets {o.min():+.0f} to {o.max():+.0f} cm, "
            f"mean {o.mean():+.1f}; data.body_girth=masks)"
        )


def _small(mask: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(H', W') bool: a mask reduced by area average (foreground where more than half is)."""
    img = Image.fromarray(mask.astype(np.float32)).resize(size, Image.Resampling.BOX)
    return np.asarray(img) > 0.5


class SilhouetteObjective:
    """Mean silhouette IoU of the body inflated by per-joint offsets against fixed masks:
    the posed vertices and normals are computed once per image."""

    def __init__(self, body, poses, trans, cameras, masks, betas=None):
        self.body, self.cameras, self.masks = body, cameras, masks
        self.verts, self.normals = posed_normals(body, poses, trans, betas)
        self.faces = body.faces

    def __call__(self, offsets) -> float:
        along = vertex_offsets(self.body, offsets)[None, :, None]
        verts = self.verts + self.normals * along
        ious = [
            overlap(body_silhouette(v, self.faces, cam), m)[0]
            for v, cam, m in zip(verts, self.cameras, self.masks, strict=True)
        ]
        return float(np.mean(ious))


def sample(capture, views: list[int]) -> SilhouetteObjective:
    """The objective on :data:`SAMPLE_IMAGES` training images (spread over the training
    frames and views, frame-major), each at most :data:`FIT_SIZE` pixels a side."""
    pairs = [(t, v) for t in capture.train_frames for v in views]
    chosen = [pairs[i] for i in spread(range(len(pairs)), SAMPLE_IMAGES)]
    frames = [t for t, _ in chosen]
    cams, masks = [], []
    for t, v in chosen:
        cam = capture.cameras[v]
        factor = min(1.0, FIT_SIZE / max(cam.width, cam.height))
        small = cam.scaled(factor)
        cams.append(small)
        masks.append(_small(capture.mask(v, t), (small.width, small.height)))
    return SilhouetteObjective(
        capture.body, capture.poses[frames], capture.trans[frames], cams, masks, capture.shape()
    )


def candidate_offsets(shell_width: float) -> np.ndarray:
    """(K,) offsets (m) from :data:`LEAST` in :data:`STEP` steps to ``shell_width`` less
    :data:`ROOM`."""
    count = int(np.floor((shell_width - ROOM - LEAST) / STEP + 1e-9)) + 1
    return np.round(LEAST + STEP * np.arange(max(count, 1)), 6)


def search(objective, num_joints: int, groups: list[list[int]], offsets) -> tuple[np.ndarray, float, float]:
    """(offsets (J,), IoU at zero, IoU at the offsets): the best uniform offset of
    ``offsets`` (K,), then :data:`SWEEPS` coordinate-wise passes over ``groups``."""
    zero = objective(np.zeros(num_joints))
    best_val, best = zero, np.zeros(num_joints)
    for o in offsets:
        if o == 0:
            continue
        val = objective(np.full(num_joints, o))
        if val > best_val:
            best_val, best = val, np.full(num_joints, o)
    for _ in range(SWEEPS):
        moved = False
        for group in groups:
            for o in offsets:
                if o == best[group[0]]:
                    continue
                trial = best.copy()
                trial[group] = o
                val = objective(trial)
                if val > best_val + 1e-4:
                    best_val, best, moved = val, trial, True
        if not moved:
            break
    return best, zero, best_val


def fit_girth(capture, settings: Settings, views: list[int]) -> GirthFit | None:
    """The girth fitted to the training masks within the field's shell
    (``settings.field.shell_width``, already fitted); None when ``data.body_girth`` is none."""
    if settings.data.body_girth == "none":
        return None
    objective = sample(capture, views)
    joints = capture.body.num_joints
    names = JOINT_NAMES if joints == len(JOINT_NAMES) else [str(j) for j in range(joints)]
    candidates = candidate_offsets(settings.field.shell_width)
    offsets, before, after = search(objective, joints, symmetric_groups(names), candidates)
    fit = GirthFit(offsets, before, after, len(objective.masks))
    log.info(fit.line())
    return fit


def apply_stored_girth(model, ck: dict, where) -> None:
    """Set the girth a checkpoint stores on its field (none: zero, as it trained)."""
    apply_stored_joint_values(model.set_girth, ck, CHECKPOINT_KEY, where)


def apply_stored_joint_values(setter, ck: dict, key: str, where) -> None:
    """``setter(values (J,) float32)`` with the per-joint values checkpoint ``ck`` stores
    under ``key`` (nothing when it stores none); a bad value is an error naming ``where``
    and the key."""
    values = ck.get(key)
    if values is None:
        return
    try:
        setter(np.asarray(values, np.float32))
    except (ValueError, TypeError) as e:
        raise TexvocabError(f"{where}: {key}: {e}") from None
