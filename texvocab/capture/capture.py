"""Capture: calibrated views × frames of one person, with per-frame SMPL poses.

Images and masks load lazily from disk (undistorted with each camera's distortion); the
training / novel-pose split is by frame, as in the paper (first frames train): by default
70 % of the frames train, or 80 % for a one-camera capture, which has no held-out view
and so holds out its last frames (:func:`default_num_train`).
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from PIL import Image

from texvocab.capture.camera import Camera
from texvocab.capture.image_reader import image_size, read_image, read_mask, verify_image
from texvocab.errors import AssetError

SYNTH_META = "texvocab_synth.json"


def default_num_train(num_frames: int, num_views: int) -> int:
    """Leading training frames of a capture without a recorded split: 70 % of the frames,
    or ⌊0.8·T⌋ with one camera (the last 20 % are its novel poses); at least 1."""
    share = 0.8 if num_views == 1 else 0.7
    return max(1, int(share * num_frames))


@dataclass
class Capture:
    """A multi-view capture.

    Attributes:
        root: folder on disk; layout: ``zju``, ``thuman`` or ``humannerf``.
        cameras: one :class:`Camera` per view.
        poses: (T, 24, 3) axis-angle per frame (SMPL order, root orientation at joint 0).
        trans: (T, 3) root translation in the project's convention (body.forward's trans).
        image_paths, mask_paths: [frame][view] files.
        frame_ids: the frame numbers used by the source layout.
        num_train: frames [0, num_train) are training poses, the rest novel poses.
        body: the :class:`~texvocab.body.BodyModel` the poses drive.
        betas: (S,) shape coefficients for SMPL bodies, or None.
        rest_joints: (24, 3) the subject's own rest (T-pose) joints in the body frame,
            metres, when the capture gives them (HumanNeRF's ``tpose_joints``), else None:
            what a body fit to this subject starts from.
        image_scale: images and masks are resized by this factor on load (``cameras`` are
            the resized ones; :meth:`scaled`); 1: as on disk.
        source_cameras: the cameras of the images on disk when ``image_scale`` != 1.
        masked: images are black outside their mask (:meth:`image`): a real capture's
            background (a studio, other people) is not the avatar's to render; synthetic
            captures are rendered on black already.
    """

    root: Path
    layout: str
    cameras: list[Camera]
    poses: np.ndarray
    trans: np.ndarray
    image_paths: list[list[Path]]
    mask_paths: list[list[Path]]
    frame_ids: list[int]
    num_train: int
    body: object
    betas: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    rest_joints: np.ndarray | None = None
    image_scale: float = 1.0
    source_cameras: list[Camera] | None = None
    masked: bool = False

    def __post_init__(self):
        t = len(self.image_paths)
        if self.poses.shape != (t, 24, 3) or self.trans.shape != (t, 3):
            raise AssetError(
                f"{self.root}: {t} frames of images but poses {self.poses.shape} and trans {self.trans.shape}"
            )
        if not np.isfinite(self.poses).all() or not np.isfinite(self.trans).all():
            f = int(np.nonzero(~(np.isfinite(self.poses).all((1, 2)) & np.isfinite(self.trans).all(1)))[0][0])
            raise AssetError(f"{self.root}: non-finite pose or translation at frame {self.frame_ids[f]}")
        if self.rest_joints is not None and (
            np.shape(self.rest_joints) != (24, 3) or not np.isfinite(self.rest_joints).all()
        ):
            raise AssetError(
                f"{self.root}: rest joints {np.shape(self.rest_joints)}; expected (24, 3) finite"
            )
        self.num_train = int(min(max(self.num_train, 0), t))  # 0: every frame is a novel pose

    @property
    def num_frames(self) -> int:
        return len(self.image_paths)

    @property
    def num_views(self) -> int:
        return len(self.cameras)

    @property
    def train_frames(self) -> range:
        return range(self.num_train)

    @property
    def novel_frames(self) -> range:
        return range(self.num_train, self.num_frames)

    def scaled(self, factor: float) -> Capture:
        """This capture with its images and masks resized by ``factor`` on load (area
        average; a mask pixel is foreground where more than half of its area is) and its
        cameras scaled to match; ``factor`` is relative to the images on disk. A 1024²
        capture at 0.5 trains and evaluates at 512²."""
        if not (0.0 < factor <= 1.0) or not np.isfinite(factor):
            raise AssetError(f"image scale {factor!r}: expected 0 < scale <= 1")
        source = self.source_cameras or self.cameras
        if factor == 1.0:
            return dataclasses.replace(self, cameras=list(source), source_cameras=None, image_scale=1.0)
        cams = [
            dataclasses.replace(c.scaled(factor), dist=np.zeros_like(c.dist)) for c in source
        ]  # images are undistorted before they are resized
        return dataclasses.replace(self, cameras=cams, source_cameras=list(source), image_scale=float(factor))

    def _source(self, view: int) -> Camera:
        return (self.source_cameras or self.cameras)[view]

    def _resized(self, image: np.ndarray, view: int) -> np.ndarray:
        """(H, W[, C]) float32 at the source size -> this capture's size for ``view``."""
        if self.source_cameras is None:
            return image
        cam = self.cameras[view]
        chans = image.reshape(image.shape[0], image.shape[1], -1)
        out = [
            np.asarray(Image.fromarray(chans[..., c]).resize((cam.width, cam.height), Image.Resampling.BOX))
            for c in range(chans.shape[2])
        ]
        return np.stack(out, -1).reshape(cam.height, cam.width, *image.shape[2:])

    def image(self, view: int, frame: int) -> np.ndarray:
        """(H, W, 3) float32 RGB, undistorted (black outside the mask when ``masked``;
        resized to ``image_scale`` after both)."""
        img = read_image(self.image_paths[frame][view])
        self.check_size(self.image_paths[frame][view], img.shape, view)
        img = self._source(view).undistort_image(img)
        if self.masked:
            img = img * self._source_mask(view, frame)[..., None]
        return self._resized(img, view)

    def _source_mask(self, view: int, frame: int) -> np.ndarray:
        """(H, W) bool foreground at the size on disk, undistorted."""
        m = read_mask(self.mask_paths[frame][view])
        self.check_size(self.mask_paths[frame][view], m.shape, view)
        return self._source(view).undistort_image(m.astype(np.uint8), nearest=True) > 0

    def mask(self, view: int, frame: int) -> np.ndarray:
        """(H, W) bool foreground, undistorted (and resized to ``image_scale``)."""
        m = self._source_mask(view, frame)
        if self.source_cameras is None:
            return m
        return self._resized(m.astype(np.float32), view) > 0.5

    def check_size(self, path: Path, shape: tuple, view: int) -> None:
        """AssetError naming ``path`` when ``shape`` (H, W[, C]) is not ``view``'s size on disk."""
        cam = self._source(view)
        if tuple(shape[:2]) != (cam.height, cam.width):
            raise AssetError(
                f"{path}: image is {shape[1]}x{shape[0]}, but view {view}'s "
                f"calibration (and its other images) say {cam.width}x{cam.height}"
            )

    def image_problems(self, frames=None, views=None, decode: bool = False, masks: bool = True) -> list[str]:
        """One line per image (and mask, with ``masks``) of ``frames`` x ``views`` (default
        all) that is missing, unreadable, over the pixel limit or not its view's size, each
        naming the file (:mod:`texvocab.capture.image_reader`); with ``decode`` every file
        is decoded too, which finds truncated and damaged ones. Empty: all are well."""
        frames = range(self.num_frames) if frames is None else frames
        views = range(self.num_views) if views is None else views
        problems = []
        for t in frames:
            for v in views:
                files = [(self.image_paths[t][v], "image")] + masks * [(self.mask_paths[t][v], "mask")]
                for path, what in files:
                    try:
                        w, h = image_size(path, what)
                        self.check_size(path, (h, w), v)
                        if decode:
                            verify_image(path, what)
                    except AssetError as e:
                        problems.append(str(e))
        return problems

    def check_image_sizes(self, frames=None, views=None) -> None:
        """Read the header of every image and mask of ``frames`` x ``views`` (default
        all) and raise AssetError naming the first that is unreadable or not its view's
        size (and how many more are): a cheap check before long work (no pixels are
        decoded)."""
        problems = self.image_problems(frames, views)
        if problems:
            more = f" (and {len(problems) - 1} more bad image files)" if len(problems) > 1 else ""
            raise AssetError(problems[0] + more)

    def shape(self) -> torch.Tensor | None:
        """(1, S) the subject's shape coefficients as the body takes them (the first
        ``body.num_betas``), or None when the capture has none or the body no shape space.
        Everything that poses this subject's body uses it (texture maps, pose feature,
        shell, field), so they all see the same mesh."""
        if self.betas is None or not self.body.num_betas:
            return None
        n = min(len(self.betas), self.body.num_betas)
        return torch.as_tensor(np.asarray(self.betas[:n]))[None]

    def posed_body(self, frame: int):
        """:class:`~texvocab.body.BodyOutput` of one frame (batch of 1)."""
        return self.body.forward(
            torch.as_tensor(self.poses[frame])[None], torch.as_tensor(self.trans[frame])[None], self.shape()
        )

    @property
    def synthetic(self) -> dict | None:
        """The generator settings when this capture was made by ``texvocab synth``."""
        return read_synth_meta(self.root)


def read_synth_meta(root: Path) -> dict | None:
    """``texvocab_synth.json`` of a capture (None when absent); AssetError when it is not
    a JSON object."""
    path = Path(root) / SYNTH_META
    if not path.is_file():
        return None
    try:
        meta = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise AssetError(
            f"{path}: not valid JSON ({e.msg if hasattr(e, 'msg') else e}); it "
            "should hold the generator's settings"
        ) from None
    if not isinstance(meta, dict):
        raise AssetError(f"{path}: expected a JSON object of generator settings")
    return meta
