"""HumanNeRF layout (as HumanNeRF's ``tools/prepare_zju_mocap/prepare_dataset.py`` writes
one camera of a ZJU-MoCap subject): reader.

root/images/frame_%06d.png   images as captured (not undistorted)
root/masks/frame_%06d.png    masks, 0/255 (any channels; foreground > 127)
root/cameras.pkl             {frame name: {intrinsics (3, 3), extrinsics (4, 4) world→camera,
                             distortions (5,)}}; spec humannerf_camera.json
root/mesh_infos.pkl          {frame name: {Rh (3,), Th (3,), poses (72,), joints (24, 3),
                             tpose_joints (24, 3)}}; spec humannerf_mesh_info.json
(canonical_joints.pkl, config.yaml and images/out.mp4 are not read.)

One camera: each frame has one image, so the per-frame cameras of ``cameras.pkl`` must be
one fixed camera (they are: the folder is one view of the capture). Frames whose camera
differs are refused, naming the frame: a moving camera does not fit a capture of fixed
views × frames. The frame number is the name's digits.

SMPL as ZJU's ``new_params``: world = R(Rh)·v + Th, v the subject's SMPL body, whose rest
pelvis is ``tpose_joints[0]`` (J0s). The reader folds Rh into joint 0 and places the
project body's pelvis (rest J0b; it rotates about it) on the subject's pelvis:
trans = Th + R(Rh)·J0s − J0b. With the subject's own body (J0b = J0s) this is the ZJU
reader's trans = Th + R(Rh)·J0 − J0. Images and masks are undistorted on load.
"""

from __future__ import annotations

import logging
import re
from pathlib import Path

import numpy as np
import torch

from texvocab.capture.calibration_checks import CameraFields, check_camera, check_views_see_subject
from texvocab.capture.camera import Camera
from texvocab.capture.capture import Capture, default_num_train
from texvocab.capture.image_reader import first_size
from texvocab.capture.mask_checks import check_mask_content
from texvocab.errors import AssetError
from texvocab.geometry.rotations import quat_multiply, quat_to_rotvec, rotvec_to_quat, rotvec_to_rotmat
from texvocab.io.safe_pickle import read_pickle
from texvocab.io.spec import require_valid

log = logging.getLogger("texvocab")

FRAME_NAME = re.compile(r"frame_(\d+)")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
CAMERA_KEYS = ("intrinsics", "extrinsics", "distortions")
#: Per-frame cameras equal within this (pixels for K, metres / unit for the rest) are one.
SAME_CAMERA_TOL = 1e-5


def is_humannerf(root: Path) -> bool:
    return (root / "cameras.pkl").is_file() and (root / "mesh_infos.pkl").is_file()


def _frame_entries(path: Path, spec: str) -> dict[str, dict[str, np.ndarray]]:
    """{frame name: {key: array}} of a HumanNeRF pickle, each entry checked against
    ``assets_spec/<spec>.json`` (shapes, dtypes, finiteness), in frame-number order."""
    data = read_pickle(path, f"HumanNeRF {path.name} (a pickled dict per frame)")
    out = {}
    for name, entry in data.items():
        if not isinstance(name, str) or not FRAME_NAME.fullmatch(name):
            raise AssetError(f"{path}: key {name!r}; expected frame names frame_%06d")
        if not isinstance(entry, dict):
            raise AssetError(f"{path}: {name} holds {type(entry).__name__}; expected a dict of arrays")
        arrays = {}
        for key, value in entry.items():
            try:
                arrays[key] = np.asarray(value)
            except ValueError:  # a ragged list
                raise AssetError(f"{path}: {name} '{key}' is not an array") from None
        require_valid(arrays, spec, f"{path}: {name}")
        out[name] = arrays
    if not out:
        raise AssetError(f"{path}: holds no frames")
    return dict(sorted(out.items(), key=lambda kv: int(kv[0][6:])))


def _camera(cams: dict[str, dict], path: Path, size: tuple[int, int]) -> Camera:
    """The one camera of every frame; AssetError naming the field or the frame that is not."""
    first, entry = next(iter(cams.items()))
    K, E = entry["intrinsics"].astype(np.float64), entry["extrinsics"].astype(np.float64)
    if np.abs(E[3] - (0, 0, 0, 1)).max() > 1e-6:
        raise AssetError(f"{path}: {first} 'extrinsics' last row is {E[3].tolist()}; expected (0, 0, 0, 1)")
    zeros = np.zeros(5)
    cam = Camera(K, E[:3, :3], E[:3, 3], size[0], size[1], entry.get("distortions", zeros), name="camera")
    check_camera(cam, str(path), _fields(first))
    for key in CAMERA_KEYS:
        ref = entry.get(key, zeros)
        stack = np.stack([c.get(key, zeros) for c in cams.values()]).astype(np.float64)
        diff = np.abs(stack - ref).reshape(len(stack), -1).max(1)
        if diff.max() > SAME_CAMERA_TOL:
            other = list(cams)[int(np.argmax(diff > SAME_CAMERA_TOL))]
            raise AssetError(
                f"{path}: {other} '{key}' differs from {first}'s by "
                f"{diff.max():.3g}; texvocab reads a HumanNeRF folder as one fixed "
                "camera (one image per frame: per-frame cameras would be a moving "
                "camera); see assets_spec/captures.md"
            )
    return cam


def _fields(frame: str) -> CameraFields:
    """How ``cameras.pkl`` names the camera's fields (those of its first frame)."""
    return CameraFields.keyed(
        f"{frame} ",
        "'intrinsics'",
        "'extrinsics'[:3, :3]",
        "'extrinsics'[:3, 3]",
        "'distortions'",
        "image size",
    )


def _files(folder: Path) -> dict[str, Path]:
    """{stem: path} of the images in a folder; AssetError when it is missing."""
    if not folder.is_dir():
        raise AssetError(f"{folder}: missing (a HumanNeRF folder has images/ and masks/)")
    return {p.stem: p for p in sorted(folder.iterdir()) if p.suffix.lower() in IMAGE_SUFFIXES}


def read_humannerf(root: Path, body, num_train: int | None = None) -> Capture:
    """Open a HumanNeRF-layout folder (module docstring). A frame whose image or mask is
    missing is left out (one warning line names them); by default the last 20 % of the
    kept frames are novel poses (:func:`~texvocab.capture.capture.default_num_train`)."""
    root = Path(root)
    cams = _frame_entries(root / "cameras.pkl", "humannerf_camera")
    infos = _frame_entries(root / "mesh_infos.pkl", "humannerf_mesh_info")
    for a, b, listed, other in (
        ("cameras.pkl", "mesh_infos.pkl", cams, infos),
        ("mesh_infos.pkl", "cameras.pkl", infos, cams),
    ):
        lacking = [n for n in listed if n not in other]
        if lacking:
            raise AssetError(
                f"{root / b}: no entry for {lacking[0]} ({len(lacking)} frame(s) of "
                f"{a} missing); the two pickles must list the same frames"
            )
    images, masks = _files(root / "images"), _files(root / "masks")
    names, left_out = [], []
    for name in infos:
        gone = [what for what, files in (("image", images), ("mask", masks)) if name not in files]
        if gone:
            left_out.append(f"{name} (no {' and no '.join(gone)})")
        else:
            names.append(name)
    if left_out:
        shown = ", ".join(left_out[:10]) + (f" and {len(left_out) - 10} more" if len(left_out) > 10 else "")
        log.warning("%s: left out %d frame(s) whose image or mask is missing: %s", root, len(left_out), shown)
    if not names:
        raise AssetError(
            f"{root}: none of the {len(infos)} frames of mesh_infos.pkl has both "
            "an image in images/ and a mask in masks/"
        )
    camera = _camera(cams, root / "cameras.pkl", first_size([images[n] for n in names]))
    info = [infos[n] for n in names]
    rest = np.stack([m["tpose_joints"] for m in info]).astype(np.float64)
    spread = np.abs(rest - rest[0]).max()
    if spread > 1e-3:
        log.warning(
            "%s: tpose_joints differ between frames by up to %.1f mm; using %s's",
            root / "mesh_infos.pkl",
            spread * 1000,
            names[0],
        )
    poses = np.stack([m["poses"].reshape(24, 3) for m in info]).astype(np.float64)
    rh = torch.as_tensor(np.stack([m["Rh"] for m in info]).astype(np.float64))
    th = np.stack([m["Th"] for m in info]).astype(np.float64)
    q = quat_multiply(rotvec_to_quat(rh), rotvec_to_quat(torch.as_tensor(poses[:, 0])))
    poses[:, 0] = quat_to_rotvec(q).numpy()
    j0_subject, j0_body = rest[0, 0], body.rest_joints[0].double().numpy()
    trans = th + rotvec_to_rotmat(rh).numpy() @ j0_subject - j0_body
    capture = Capture(
        root=root,
        layout="humannerf",
        cameras=[camera],
        poses=poses.astype(np.float32),
        trans=trans.astype(np.float32),
        image_paths=[[images[n]] for n in names],
        mask_paths=[[masks[n]] for n in names],
        frame_ids=[int(n[6:]) for n in names],
        num_train=default_num_train(len(names), 1) if num_train is None else num_train,
        body=body,
        rest_joints=rest[0],
    )
    check_views_see_subject(capture, str(root / "cameras.pkl"), [_fields(next(iter(cams)))])
    check_mask_content(capture)
    return capture
