"""Synthetic multi-view captures with ground truth at any pose (``texvocab synth``).

The body wears procedural clothing (:mod:`texvocab.capture.garment`) whose folds follow
the joint rotations; pyrender draws it offscreen (OSMesa/EGL) under fixed world lights
from a ring of cameras plus raised ones.
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from texvocab.body.pose_files import read_pose_sequence
from texvocab.capture.camera import Camera
from texvocab.capture.capture import SYNTH_META
from texvocab.capture.fold_regions import FoldRegions, fold_region
from texvocab.capture.garment import Garment
from texvocab.capture.garment_mesh import ClothMesh
from texvocab.capture.garment_sets import DEFAULT_GARMENT, garment_spec
from texvocab.capture.synth_realism import CameraEffects, noisy_fit
from texvocab.capture.thuman import ThumanWriter
from texvocab.capture.zju import ZjuWriter
from texvocab.errors import AssetError
from texvocab.io.full_disk import disk_full_error, is_disk_full
from texvocab.io.gl_platform import ensure_offscreen
from texvocab.io.stop_flag import raise_if_stopped
from texvocab.io.temp_files import sweep_stale, temp_dir

LAYOUTS = ("zju", "thuman")


@dataclass
class SynthSettings:
    """Generator knobs. ``size`` is the image side in pixels; ``texture_size`` the
    clothing texture's; cameras sit on a ring of ``radius`` metres around the body."""

    ring_views: int = 8
    raised_views: int = 2
    size: int = 256
    radius: float = 3.2
    fov_deg: float = 40.0
    texture_size: int = 1024
    seed: int = 0
    target_y: float = -0.3
    lighting: bool = True  # False: unlit albedo (tests compare texture maps to it)
    garment: str = DEFAULT_GARMENT  # texvocab.capture.garment_sets
    cloth_slide: float = 0.0  # metres at full bend (texvocab.capture.cloth_slide); 0: cloth stays put
    # texvocab.capture.synth_realism (all 0: the truth, clean images)
    fit_noise_deg: float = 0.0
    fit_noise_trans: float = 0.0
    exposure_sd: float = 0.0
    white_balance_sd: float = 0.0
    sensor_noise: float = 0.0
    fold_regions: bool = True  # store fold_regions.npz (texvocab.metrics.fold_region)


def default_cameras(s: SynthSettings) -> list[Camera]:
    """``ring_views`` cameras at chest height on a ring, ``raised_views`` higher up."""
    # late: mesh_renderer imports pyrender, binding PyOpenGL to OSMesa; load_pose_file (viewer) must not
    from texvocab.capture.mesh_renderer import intrinsics, look_at

    K = intrinsics(s.size, s.size, s.fov_deg)
    target = np.array([0.0, s.target_y, 0.0])
    cams = []
    for v in range(s.ring_views + s.raised_views):
        raised = v >= s.ring_views
        n = s.raised_views if raised else s.ring_views
        k = v - s.ring_views if raised else v
        az = 2 * np.pi * k / n + (np.pi / 4 if raised else 0.0)
        height = 1.3 if raised else 0.1
        eye = target + np.array([s.radius * np.sin(az), height, s.radius * np.cos(az)])
        R, t = look_at(eye, target)
        cams.append(Camera(K, R, t, s.size, s.size, name=f"view{v}"))
    return cams


def _split_seams(faces: np.ndarray, ft: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Render-mesh vertices = unique (vertex, uv) pairs. Returns vertex index (R,),
    uv index (R,) and faces (F, 3) into the render vertices."""
    pairs = np.stack([faces.reshape(-1), ft.reshape(-1)], 1)
    uniq, inverse = np.unique(pairs, axis=0, return_inverse=True)
    return uniq[:, 0], uniq[:, 1], inverse.reshape(-1, 3)


class SynthRenderer:
    """Renders the clothed body at any pose from any camera (ground truth for evaluation)."""

    def __init__(self, body, settings: SynthSettings | None = None):
        ensure_offscreen()
        # late: PyOpenGL binds its platform at first import, after ensure_offscreen;
        # mesh_renderer also quiets trimesh's logger (see there)
        from texvocab.capture.mesh_renderer import pyrender

        self._pr = pyrender
        self.body = body
        self.settings = settings or SynthSettings()
        spec = garment_spec(self.settings.garment)
        self.garment = Garment(body, self.settings.texture_size)
        self.cloth = None if spec is None else ClothMesh(body, spec)
        self.vidx, uvidx, self.rfaces = _split_seams(body.faces.numpy(), body.ft.numpy())
        self.uv = body.vt.numpy()[uvidx]
        self._renderer = None
        self._size = None

    def _ensure_renderer(self, w: int, h: int):
        if self._size != (w, h):
            if self._renderer is not None:
                self._renderer.delete()
            self._renderer = self._pr.OffscreenRenderer(w, h)
            self._size = (w, h)
        return self._renderer

    def render(
        self, pose, trans, cameras: list[Camera], texture_pose=None
    ) -> list[tuple[np.ndarray, np.ndarray]]:
        """[(rgb (H, W, 3) float32, mask (H, W) bool)] per camera for one pose (24, 3).

        ``texture_pose`` (tests, inspection, fold regions): take the clothing's folds from
        another pose while keeping this pose's body (painted folds in the albedo, or a
        garment's fold ridges on its cloth).
        """
        import trimesh  # late: ~1 s to import, needed only with pyrender (not by load_pose_file)

        pr = self._pr
        fold_pose = pose if texture_pose is None else texture_pose
        if self.cloth is None:  # painted: the body mesh, folds in the albedo
            out = self.body.forward(torch.as_tensor(pose)[None], torch.as_tensor(trans)[None])
            verts = out.vertices[0].double().numpy()
            normals = trimesh.Trimesh(verts, self.body.faces.numpy(), process=False).vertex_normals
            tex = self.garment.texture(fold_pose, self.settings.cloth_slide)
            positions, normals, uv, faces = verts[self.vidx], normals[self.vidx], self.uv, self.rfaces
        else:  # cloth geometry: folds are ridges of the surface, the albedo is static
            positions, normals = self.cloth.posed(pose, trans, fold_pose)
            tex = self.garment.albedo_at(fold_pose, self.settings.cloth_slide)
            uv, faces = self.cloth.uv, self.cloth.faces
        # pyrender samples row 0 at v = 1, the project's convention (texvocab.geometry.uv).
        texture = pr.Texture(source=(tex * 255 + 0.5).astype(np.uint8), source_channels="RGB")
        material = pr.MetallicRoughnessMaterial(
            baseColorTexture=texture, metallicFactor=0.0, roughnessFactor=0.9
        )
        prim = pr.Primitive(
            positions=positions,
            normals=normals,
            texcoord_0=uv,
            indices=faces,
            material=material,
        )
        scene = pr.Scene(bg_color=[0.0, 0.0, 0.0, 0.0], ambient_light=[0.32, 0.32, 0.32])
        scene.add(pr.Mesh([prim]))
        for direction, intensity in (((-0.4, -0.6, -0.7), 2.6), ((0.6, -0.3, 0.75), 1.2)):
            d = np.asarray(direction) / np.linalg.norm(direction)
            light_pose = np.eye(4)
            z = -d
            x = np.cross([0.0, 1.0, 0.0], z)
            x /= np.linalg.norm(x)
            light_pose[:3, :3] = np.stack([x, np.cross(z, x), z], 1)
            scene.add(pr.DirectionalLight(color=np.ones(3), intensity=intensity), pose=light_pose)
        # late: mesh_renderer imports pyrender (see default_cameras)
        from texvocab.capture.mesh_renderer import gl_camera_pose, gl_principal_point

        results = []
        cam_node = None
        for cam in cameras:
            renderer = self._ensure_renderer(cam.width, cam.height)
            if cam_node is not None:
                scene.remove_node(cam_node)
            gl_cam = pr.IntrinsicsCamera(
                cam.K[0, 0], cam.K[1, 1], *gl_principal_point(cam.K), znear=0.05, zfar=100.0
            )
            cam_node = scene.add(gl_cam, pose=gl_camera_pose(cam.R, cam.t))
            flags = pr.RenderFlags.NONE if self.settings.lighting else pr.RenderFlags.FLAT
            rgb, depth = renderer.render(scene, flags=flags)
            mask = depth > 0
            rgb = rgb.astype(np.float32) / 255.0
            rgb[~mask] = 0.0
            results.append((rgb, mask))
        return results

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.delete()
            self._renderer = None


def _check_replaceable(out: Path, overwrite: bool, while_rendering: bool = False) -> None:
    """AssetError unless ``out`` is free, or ``overwrite`` and it is a capture texvocab
    synthesised (or an empty folder). Checked again before the rename, so a folder the user
    made at ``out`` while the capture rendered is never replaced."""
    when = " (it appeared while the capture rendered)" if while_rendering else ""
    if out.is_symlink() and overwrite:
        raise AssetError(
            f"{out}: is a symbolic link (to {os.readlink(out)}){when}; --overwrite replaces a folder, "
            "not a link: give the folder itself; nothing was changed"
        )
    if out.exists() and not overwrite:
        raise AssetError(f"{out} already exists{when}; pass --overwrite to replace it; nothing was changed")
    if out.exists() and not (out.is_dir() and ((out / SYNTH_META).is_file() or not any(out.iterdir()))):
        raise AssetError(
            f"{out}: --overwrite replaces only a capture texvocab synthesised (it "
            f"holds {SYNTH_META}); this is not one{when}, so nothing was changed"
        )


def synthesize(
    out: str | Path,
    poses: np.ndarray,
    trans: np.ndarray,
    num_train: int,
    body,
    settings: SynthSettings | None = None,
    layout: str = "zju",
    cameras: list[Camera] | None = None,
    overwrite: bool = False,
    progress: bool = True,
    body_source: str = "default",
) -> Path:
    """Render a capture and write it in ``layout``; the folder appears only when complete.

    Args:
        out: capture folder to create.
        poses: (T, 24, 3) axis-angle; trans: (T, 3).
        num_train: frames [0, num_train) are training frames (recorded in the metadata).
    """
    settings = settings or SynthSettings()
    out = Path(out)
    if layout not in LAYOUTS:
        raise AssetError(f"unknown capture layout {layout!r}; expected one of {LAYOUTS}")
    poses = np.asarray(poses, np.float32)
    trans = np.asarray(trans, np.float32)
    if poses.ndim != 3 or poses.shape[1:] != (24, 3) or trans.shape != (len(poses), 3):
        raise AssetError(f"poses must be (T, 24, 3) and trans (T, 3), got {poses.shape} and {trans.shape}")
    body.check_pose(torch.as_tensor(poses), torch.as_tensor(trans))
    _check_replaceable(out, overwrite)
    cameras = cameras or default_cameras(settings)
    out.parent.mkdir(parents=True, exist_ok=True)
    sweep_stale(out.parent)  # captures half-made by a killed synth
    tmp = temp_dir(out)
    renderer = SynthRenderer(body, settings)
    s = settings
    rec_poses, rec_trans = poses, trans
    if s.fit_noise_deg > 0 or s.fit_noise_trans > 0:
        rec_poses, rec_trans = noisy_fit(poses, trans, s.fit_noise_deg, s.fit_noise_trans, s.seed)
    effects = CameraEffects(len(cameras), s.exposure_sd, s.white_balance_sd, s.sensor_noise, s.seed)
    rest = np.zeros((24, 3), np.float32)
    regions = []
    try:
        writer = (ZjuWriter if layout == "zju" else ThumanWriter)(tmp, cameras, body)
        frames = range(len(poses))
        if progress:
            frames = tqdm(frames, desc=f"synth {out.name}", unit="frame")
        for t in frames:
            renders = renderer.render(poses[t], trans[t], cameras)
            if s.fold_regions and t >= num_train:  # novel frame: where the truth depends on pose
                flat = renderer.render(poses[t], trans[t], cameras, texture_pose=rest)
                regions.append([fold_region(a[0], b[0]) for a, b in zip(renders, flat, strict=True)])
            if effects.active:
                renders = [(effects.apply(v, rgb), mask) for v, (rgb, mask) in enumerate(renders)]
            writer.add_frame(t, rec_poses[t], rec_trans[t], renders)
        writer.finish()
        if regions:
            FoldRegions.save(tmp, range(num_train, len(poses)), range(len(cameras)), np.asarray(regions))
        meta = {
            "generator": "texvocab synth",
            "layout": layout,
            "num_train": int(num_train),
            "num_frames": len(poses),
            "body": body_source,
            "settings": asdict(settings),
            "cameras": [c.to_dict() for c in cameras],
        }
        if effects.active:
            meta["camera_effects"] = effects.to_dict()
        if rec_poses is not poses:  # for analysis only: no reader returns these
            meta["true_poses"] = poses.reshape(len(poses), -1).tolist()
            meta["true_trans"] = trans.tolist()
        (tmp / SYNTH_META).write_text(json.dumps(meta, indent=1))
        _check_replaceable(out, overwrite, while_rendering=True)  # made meanwhile: the user's
        if out.exists():
            shutil.rmtree(out)
        raise_if_stopped()  # a stop signal that a library swallowed (texvocab.io.stop_flag)
        tmp.rename(out)
    except BaseException as e:
        shutil.rmtree(tmp, ignore_errors=True)
        if is_disk_full(e):
            raise disk_full_error(out, e, "nothing was written (the partial capture is removed)") from None
        raise
    finally:
        renderer.close()
    return out


def settings_of(capture) -> tuple[SynthSettings, list[Camera]]:
    """The generator settings and cameras recorded in a synthetic capture."""
    meta = capture.synthetic if hasattr(capture, "synthetic") else capture
    if not meta:
        raise AssetError(
            f"{getattr(capture, 'root', capture)} was not made by texvocab synth: "
            "no ground truth can be rendered for new poses"
        )
    cams = [
        Camera(c["K"], c["R"], c["t"], c["width"], c["height"], c["dist"], c["name"]) for c in meta["cameras"]
    ]
    return SynthSettings(**meta["settings"]), cams


def ground_truth_renderer(capture) -> tuple[SynthRenderer, list[Camera]]:
    """A renderer that reproduces ``capture`` at any pose, and the capture's cameras.

    Novel-pose metrics compare against these true images, not guesses.
    """
    settings, cams = settings_of(capture)
    return SynthRenderer(capture.body, settings), cams


def load_pose_file(path: str | Path, fps: float | None = 30.0) -> tuple[np.ndarray, np.ndarray]:
    """Poses (T, 24, 3) and trans (T, 3), +Y up, of any pose file
    :func:`texvocab.body.pose_files.read_pose_sequence` reads (SMPL, AMASS SMPL-H,
    SMPL-X), resampled to ``fps`` when the file states its frame rate."""
    seq = read_pose_sequence(path, fps=fps)
    return seq.poses, seq.trans
