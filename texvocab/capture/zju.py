"""ZJU-MoCap layout (as read by animatable_nerf / neuralbody): reader and writer.

root/annots.npy            pickled dict: cams {K, D, R, T (millimetres)}, ims [{ims: [...]}]
root/<view>/<frame>.jpg    images, paths as listed in annots['ims']
root/mask_cihp/ or mask/   masks at the image's relative path with a .png suffix
root/params/{i}.npy        or new_params/: {poses (1, 72), Rh (1, 3), Th (1, 3), shapes (1, 10)}

ZJU's SMPL has zero root pose and puts the global rotation in Rh about the origin:
world = R(Rh) · v_smpl + Th. The project's body rotates about the pelvis joint J0 and
then adds trans, so trans = Th + R(Rh) J0 − J0 (J0 of the body in use).
"""

from __future__ import annotations

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
from texvocab.io.images import save_png
from texvocab.io.safe_pickle import read_npy_object
from texvocab.io.spec import require_valid, spec_ref

MASK_DIRS = ("mask_cihp", "mask")
PARAM_DIRS = ("new_params", "params")


def is_zju(root: Path) -> bool:
    return (root / "annots.npy").is_file()


def _rest_pelvis(body, betas) -> np.ndarray:
    if betas is not None and body.num_betas:
        n = min(len(betas), body.num_betas)
        _, joints = body.shaped(torch.as_tensor(betas[:n], dtype=body.dtype)[None], 1)
        return joints[0, 0].double().numpy()
    return body.rest_joints[0].double().numpy()


def _cameras(annots: dict, path: Path, num_views: int, size: tuple[int, int]) -> list[Camera]:
    cams = annots.get("cams")
    if not isinstance(cams, dict) or not all(k in cams for k in ("K", "R", "T")):
        raise AssetError(f"{path}: 'cams' must hold K, R, T (and D) lists")
    for k in ("K", "R", "T", "D"):
        if k in cams and not isinstance(cams[k], list | tuple | np.ndarray):
            raise AssetError(
                f"{path}: cams['{k}'] holds {type(cams[k]).__name__}; expected a list with one entry per view"
            )
    counts = {k: len(cams[k]) for k in ("K", "R", "T", "D") if k in cams}
    if len(set(counts.values())) != 1 or num_views != counts["K"]:
        raise AssetError(
            f"{path}: camera count mismatch: cams has {counts} entries but each "
            f"frame lists {num_views} images"
        )
    out = []
    for v in range(num_views):
        arrays = {}
        for key, shape in (("K", (3, 3)), ("R", (3, 3)), ("T", (3,)), ("D", None)):
            if key not in cams:
                continue
            try:
                a = np.asarray(cams[key][v], dtype=np.float64)
            except (TypeError, ValueError):
                raise AssetError(f"{path}: cams['{key}'][{v}] is not numeric") from None
            if shape is not None and a.size != int(np.prod(shape)):
                raise AssetError(
                    f"{path}: cams['{key}'][{v}] has shape {a.shape}; expected "
                    f"{shape}{' (or (3, 1))' if key == 'T' else ''}"
                )
            arrays[key] = a.reshape(shape) if shape is not None else a.reshape(-1)
        dist = arrays.get("D", np.zeros(5))
        cam = Camera(arrays["K"], arrays["R"], arrays["T"] / 1000.0, size[0], size[1], dist, name=f"view{v}")
        out.append(check_camera(cam, str(path), _fields(v)))
    return out


def _fields(v: int) -> CameraFields:
    """How ``annots.npy`` names view ``v``'s calibration."""
    return CameraFields(
        f"cams['K'][{v}]",
        f"cams['R'][{v}]",
        f"cams['T'][{v}]",
        f"cams['D'][{v}]",
        f"the size of view {v}'s images",
    )


def read_zju(root: Path, body, num_train: int | None = None) -> Capture:
    """Open a ZJU-MoCap capture folder."""
    annots_path = root / "annots.npy"
    annots = read_npy_object(annots_path)
    if not isinstance(annots, dict) or "ims" not in annots:
        raise AssetError(f"{annots_path}: expected a dict with 'cams' and 'ims'")
    rows = annots["ims"]
    if not isinstance(rows, list | tuple) or not all(
        isinstance(e, dict)
        and isinstance(e.get("ims"), list | tuple)
        and all(isinstance(p, str) for p in e["ims"])
        for e in rows
    ):
        raise AssetError(
            f"{annots_path}: 'ims' must be a list of {{'ims': [image paths]}} per "
            f"frame, got {type(rows).__name__}"
        )
    ims = [entry["ims"] for entry in rows]
    if not ims:
        raise AssetError(f"{annots_path}: 'ims' lists no frames")
    num_views = len(ims[0])
    for t, row in enumerate(ims):
        if len(row) != num_views:
            raise AssetError(
                f"{annots_path}: frame {t} lists {len(row)} images, frame 0 lists "
                f"{num_views} (frame count mismatch between views)"
            )
    view_dirs = [root / Path(p).parent for p in ims[0]]
    for v, d in enumerate(view_dirs):
        if not d.is_dir():
            raise AssetError(f"{annots_path}: missing view folder {d} (view {v})")
        found = len([f for f in d.iterdir() if f.suffix.lower() in (".jpg", ".png", ".jpeg")])
        if found < len(ims):
            raise AssetError(
                f"{d}: {found} images but {annots_path.name} lists {len(ims)} frames "
                "(frame count mismatch between views)"
            )
    size = first_size([root / row[0] for row in ims])
    cameras = _cameras(annots, annots_path, num_views, size)
    mask_dir = next((root / m for m in MASK_DIRS if (root / m).is_dir()), None)
    if mask_dir is None:
        raise AssetError(f"{root}: no mask folder (expected one of {', '.join(MASK_DIRS)})")
    param_dir = next((root / p for p in PARAM_DIRS if (root / p).is_dir()), None)
    if param_dir is None:
        raise AssetError(f"{root}: no SMPL parameter folder (expected params/ or new_params/)")
    offset = 0 if (param_dir / "0.npy").is_file() else 1  # some ZJU sequences count from 1
    poses, trans, betas = [], [], None
    for t in range(len(ims)):
        ppath = param_dir / f"{t + offset}.npy"
        if not ppath.is_file():
            raise AssetError(f"{ppath}: missing SMPL parameters for frame {t}")
        p = read_npy_object(ppath)
        if not isinstance(p, dict):
            raise AssetError(f"{ppath}: expected a pickled dict; see {spec_ref('zju_params')}")
        require_valid(p, "zju_params", str(ppath))
        pose = np.asarray(p["poses"], dtype=np.float64).reshape(24, 3)
        rh = np.asarray(p["Rh"], dtype=np.float64).reshape(3)
        th = np.asarray(p["Th"], dtype=np.float64).reshape(3)
        if betas is None and "shapes" in p:
            betas = np.asarray(p["shapes"], dtype=np.float64).reshape(-1)
        q = quat_multiply(rotvec_to_quat(torch.as_tensor(rh)), rotvec_to_quat(torch.as_tensor(pose[0])))
        pose[0] = quat_to_rotvec(q).numpy()
        j0 = _rest_pelvis(body, betas)
        trans.append(th + rotvec_to_rotmat(torch.as_tensor(rh)).numpy() @ j0 - j0)
        poses.append(pose)
    masks = [[mask_dir / Path(p).with_suffix(".png") for p in row] for row in ims]
    capture = Capture(
        root=root,
        layout="zju",
        cameras=cameras,
        poses=np.asarray(poses, np.float32),
        trans=np.asarray(trans, np.float32),
        image_paths=[[root / p for p in row] for row in ims],
        mask_paths=masks,
        frame_ids=list(range(offset, offset + len(ims))),
        num_train=(default_num_train(len(ims), num_views) if num_train is None else num_train),
        body=body,
        betas=betas,
    )
    check_views_see_subject(capture, str(annots_path), [_fields(v) for v in range(num_views)])
    check_mask_content(capture)
    return capture


class ZjuWriter:
    """Writes frames into a ZJU-MoCap folder (PNG images so ground truth stays lossless)."""

    def __init__(self, root: Path, cameras: list[Camera], body):
        self.root, self.cameras, self.body = root, cameras, body
        self.ims: list[dict] = []
        self.names = [f"Camera_B{v + 1}" for v in range(len(cameras))]

    def add_frame(self, t: int, pose: np.ndarray, trans: np.ndarray, renders) -> None:
        row = []
        for name, (rgb, mask) in zip(self.names, renders):
            rel = f"{name}/{t:06d}.png"
            save_png(self.root / rel, rgb)
            save_png(self.root / "mask" / rel, mask.astype(np.uint8) * 255)
            row.append(rel)
        self.ims.append({"ims": row})
        j0 = _rest_pelvis(self.body, None)
        rh = np.asarray(pose[0], np.float64)
        th = np.asarray(trans, np.float64) - rotvec_to_rotmat(torch.as_tensor(rh)).numpy() @ j0 + j0
        poses = np.asarray(pose, np.float64).copy()
        poses[0] = 0.0
        params = {
            "poses": poses.reshape(1, 72),
            "Rh": rh.reshape(1, 3),
            "Th": th.reshape(1, 3),
            "shapes": np.zeros((1, 10)),
        }
        (self.root / "params").mkdir(parents=True, exist_ok=True)
        np.save(self.root / "params" / f"{t}.npy", params, allow_pickle=True)

    def finish(self) -> None:
        cams = {
            "K": [c.K for c in self.cameras],
            "R": [c.R for c in self.cameras],
            "T": [c.t.reshape(3, 1) * 1000.0 for c in self.cameras],
            "D": [c.dist.reshape(5, 1) for c in self.cameras],
        }
        np.save(self.root / "annots.npy", {"cams": cams, "ims": self.ims}, allow_pickle=True)
