"""THUman4.0 / AvatarReX layout: reader and writer.

root/calibration.json         {camXX: {K: 9 (row-major), R: 9, T: 3, imgSize: [W, H]}}
root/images/camXX/%08d.jpg    images;  root/masks/camXX/%08d.jpg  masks
root/smpl_params.npz          SMPL-X fits: betas, global_orient, transl, body_pose (N, 63), ...

SMPL-X and SMPL share body joints 0–21, so global_orient → joint 0 and body_pose →
joints 1–21. SMPL's joints 22–23 (left/right hand) have no SMPL-X body_pose entry: the
SMPL-X hand poses drive finger joints SMPL does not have, so 22–23 are set to zero.
Like SMPL-X, the root rotates about the pelvis and ``transl`` is added afterwards, which
is the project's convention: trans = transl. The SMPL-X ``betas`` are not fed into the
body's shape space (another body's): with the user's SMPL-X model file they give the
subject's rest joints, which the body is fitted to (:mod:`texvocab.body.smplx_joints`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from PIL import Image

from texvocab.capture.calibration_checks import CameraFields, check_camera, check_views_see_subject
from texvocab.capture.camera import Camera
from texvocab.capture.capture import Capture, default_num_train
from texvocab.capture.mask_checks import check_mask_content
from texvocab.errors import AssetError
from texvocab.io.images import atomic_write_bytes, to_uint8
from texvocab.io.safe_pickle import read_npz
from texvocab.io.spec import require_valid

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")


def is_thuman(root: Path) -> bool:
    return (root / "calibration.json").is_file()


def _frames_of(folder: Path) -> list[Path]:
    """The images of a view folder by frame number; AssetError when it has none or a name
    that is not a frame number."""
    files = [f for f in folder.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES]
    if not files:
        raise AssetError(
            f"{folder}: no images ({', '.join(IMAGE_SUFFIXES)}); expected one per frame, %08d.jpg"
        )
    for f in files:
        if not (f.stem.isascii() and f.stem.isdigit()):
            raise AssetError(f"{f}: name {f.stem!r} is not a frame number; expected %08d.jpg")
    return sorted(files, key=lambda f: int(f.stem))


def _fields(name: str) -> CameraFields:
    """How ``calibration.json`` names camera ``name``'s fields."""
    return CameraFields.keyed("", "'K'", "'R'", "'T'", "'D'", "'imgSize'")


def _calibration(path: Path) -> dict[str, dict]:
    """``calibration.json``: {camera name: {K, R, T, imgSize[, D]}}, or AssetError."""
    try:
        calib = json.loads(path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise AssetError(
            f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start}); expected JSON"
        ) from None
    except json.JSONDecodeError as exc:
        raise AssetError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(calib, dict) or not calib:
        raise AssetError(
            f"{path}: holds {type(calib).__name__}{' (empty)' if not calib else ''}; expected a "
            "JSON object {camera name: {K, R, T, imgSize}}"
        )
    for name, entry in calib.items():
        if not isinstance(entry, dict):
            raise AssetError(f"{path}: camera {name!r} holds {type(entry).__name__}; expected an object")
    return calib


def read_thuman(root: Path, body, num_train: int | None = None) -> Capture:
    """Open a THUman4.0-style capture folder."""
    calib_path = root / "calibration.json"
    calib = _calibration(calib_path)
    names = sorted(calib)
    image_dirs = (
        sorted(d.name for d in (root / "images").iterdir() if d.is_dir())
        if (root / "images").is_dir()
        else []
    )
    if len(image_dirs) != len(names):
        raise AssetError(
            f"{calib_path}: camera count mismatch: {len(names)} calibrated cameras, "
            f"{len(image_dirs)} folders in {root / 'images'}"
        )
    frames = None
    cameras, image_paths, mask_paths = [], [], []
    for name in names:
        img_dir, mask_dir = root / "images" / name, root / "masks" / name
        for d in (img_dir, mask_dir):
            if not d.is_dir():
                raise AssetError(f"{calib_path}: missing view folder {d} for camera {name}")
        imgs, masks = _frames_of(img_dir), _frames_of(mask_dir)
        if frames is None:
            frames = [int(p.stem) for p in imgs]
        if [int(p.stem) for p in imgs] != frames or len(masks) != len(imgs):
            raise AssetError(
                f"{img_dir}: {len(imgs)} images and {len(masks)} masks, but "
                f"{names[0]} has {len(frames)} frames (frame count mismatch "
                "between views)"
            )
        c = calib[name]
        try:
            w, h = c["imgSize"]
            cam = Camera(
                np.reshape(c["K"], (3, 3)),
                np.reshape(c["R"], (3, 3)),
                np.reshape(c["T"], 3),
                w,
                h,
                c.get("D", np.zeros(5)),
                name=name,
            )
        except (KeyError, ValueError, TypeError, OverflowError) as exc:
            raise AssetError(
                f"{calib_path}: camera {name} needs K (9), R (9), T (3), "
                f"imgSize [W, H] ({type(exc).__name__}: {exc})"
            ) from None
        cameras.append(check_camera(cam, str(calib_path), _fields(name)))
        image_paths.append(imgs)
        mask_paths.append(masks)
    params_path = root / "smpl_params.npz"
    p = read_npz(params_path, "SMPL-X fits (smpl_params.npz)")
    require_valid(p, "thuman_smpl_params", str(params_path))
    n = len(frames)
    if len(p["body_pose"]) < max(frames) + 1:
        raise AssetError(
            f"{params_path}: {len(p['body_pose'])} poses but images go up to frame {max(frames)}"
        )
    poses = np.zeros((n, 24, 3), np.float32)
    idx = np.asarray(frames)
    poses[:, 0] = p["global_orient"][idx]
    poses[:, 1:22] = p["body_pose"][idx].reshape(n, 21, 3)
    # SMPL-X betas are not SMPL's: kept aside for the body fit (texvocab.capture.subject)
    betas = p["betas"].reshape(-1, p["betas"].shape[-1])[0] if "betas" in p else None
    capture = Capture(
        root=root,
        layout="thuman",
        cameras=cameras,
        poses=poses,
        trans=p["transl"][idx].astype(np.float32),
        image_paths=[list(r) for r in zip(*image_paths)],
        mask_paths=[list(r) for r in zip(*mask_paths)],
        frame_ids=frames,
        num_train=default_num_train(n, len(cameras)) if num_train is None else num_train,
        body=body,
        meta={} if betas is None else {"smplx_betas": np.asarray(betas, np.float64)},
    )
    check_views_see_subject(capture, str(calib_path), [_fields(name) for name in names])
    check_mask_content(capture)
    return capture


class ThumanWriter:
    """Writes frames into a THUman4.0 folder (JPEG images and masks, as the dataset)."""

    def __init__(self, root: Path, cameras: list[Camera], body):
        self.root, self.cameras = root, cameras
        self.names = [f"cam{v:02d}" for v in range(len(cameras))]
        self.poses: list[np.ndarray] = []
        self.trans: list[np.ndarray] = []

    def add_frame(self, t: int, pose, trans, renders) -> None:
        for name, (rgb, mask) in zip(self.names, renders):
            for sub, arr in (("images", to_uint8(rgb)), ("masks", mask.astype(np.uint8) * 255)):
                img = Image.fromarray(arr)
                atomic_write_bytes(
                    self.root / sub / name / f"{t:08d}.jpg",
                    lambda tmp, img=img: img.save(tmp, format="JPEG", quality=95),
                )
        self.poses.append(np.asarray(pose))
        self.trans.append(np.asarray(trans))

    def finish(self) -> None:
        calib = {
            n: {
                "K": c.K.reshape(-1).tolist(),
                "R": c.R.reshape(-1).tolist(),
                "T": c.t.tolist(),
                "imgSize": [c.width, c.height],
            }
            for n, c in zip(self.names, self.cameras)
        }
        (self.root / "calibration.json").write_text(json.dumps(calib, indent=1))
        poses = np.asarray(self.poses, np.float32)
        n = len(poses)
        np.savez(
            self.root / "smpl_params.npz",
            betas=np.zeros((1, 10), np.float32),
            global_orient=poses[:, 0],
            transl=np.asarray(self.trans, np.float32),
            body_pose=poses[:, 1:22].reshape(n, 63),
            left_hand_pose=np.zeros((n, 45), np.float32),
            right_hand_pose=np.zeros((n, 45), np.float32),
            jaw_pose=np.zeros((n, 3), np.float32),
            expression=np.zeros((n, 10), np.float32),
        )
