"""A ZJU-MoCap subject in the HumanNeRF layout, written by the tests from a synthetic person
(one 64² camera, 10 frames): what prepare_dataset.py writes, with an optional lens and a
subject whose skeleton differs from the body's."""

import pickle

import numpy as np
import torch
from scipy import ndimage

from texvocab.capture.camera import sample_image
from texvocab.capture.motion import make_sequence
from texvocab.capture.synth import SynthRenderer, SynthSettings, default_cameras
from texvocab.geometry.rotations import rotvec_to_rotmat
from texvocab.io.images import save_png

SETTINGS = SynthSettings(ring_views=1, raised_views=0, size=64, texture_size=128)
FRAMES = 10
DIST = np.array([-0.45, 0.15, 0.003, -0.002, 0.0])


def make_truth(body):
    """(poses (T, 24, 3), trans (T, 3), camera, [(rgb, mask)] per frame) of the person."""
    poses, trans = make_sequence([("walk", 5), ("squat", 5)], seed=4)
    cam = default_cameras(SETTINGS)[0]
    renderer = SynthRenderer(body, SETTINGS)
    renders = [renderer.render(poses[t], trans[t], [cam])[0] for t in range(FRAMES)]
    renderer.close()
    return poses[:FRAMES], trans[:FRAMES], cam, renders


def distort(image: np.ndarray, cam, dist: np.ndarray) -> np.ndarray:
    """What a lens with ``dist`` records of an ideal pinhole image (H, W[, C]): the pixel at
    distorted position q shows the ideal image at D⁻¹(q) (fixed-point inversion)."""
    h, w = image.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    q = np.stack([(xs.ravel() - cam.K[0, 2]) / cam.K[0, 0], (ys.ravel() - cam.K[1, 2]) / cam.K[1, 1]], -1)
    lens = type(cam)(cam.K, cam.R, cam.t, w, h, dist)
    p = q.copy()
    for _ in range(40):
        p = p + (q - lens.distort_normalized(p))
    x, y = p[:, 0] * cam.K[0, 0] + cam.K[0, 2], p[:, 1] * cam.K[1, 1] + cam.K[1, 2]
    return sample_image(image, x, y, nearest=image.dtype == bool).reshape(image.shape)


def smooth(rgb: np.ndarray) -> np.ndarray:
    """A rendered image blurred (σ 1.5 px) so that a pixel's worth of lens shift shows
    above the blur of resampling it twice."""
    return ndimage.gaussian_filter(rgb, (1.5, 1.5, 0))


def write_standin(root, body, truth, dist=None, pelvis_offset=(0.0, 0.0, 0.0)):
    """The truth in the HumanNeRF layout, as prepare_dataset.py writes it: SMPL root pose
    zero, the root orientation in Rh, world = R(Rh)·v + Th with v's rest pelvis at
    tpose_joints[0] (shifted by ``pelvis_offset`` to stand for another subject's pelvis:
    the body's pelvis must then land on it). With ``dist``, the images (:func:`smooth`)
    and masks are distorted as that lens records them."""
    poses, trans, cam, renders = truth
    rest = body.rest_joints.double().numpy().copy()
    rest += np.asarray(pelvis_offset)  # the whole skeleton moves with the pelvis
    dist = np.zeros(5) if dist is None else np.asarray(dist)
    cams, infos = {}, {}
    for t in range(FRAMES):
        name = f"frame_{t:06d}"
        rgb, mask = renders[t]
        if dist.any():
            rgb, mask = distort(smooth(rgb), cam, dist), distort(mask, cam, dist)
        save_png(root / "images" / f"{name}.png", rgb)
        save_png(root / "masks" / f"{name}.png", np.repeat(mask[..., None], 3, -1).astype(np.uint8) * 255)
        E = np.eye(4)
        E[:3, :3], E[:3, 3] = cam.R, cam.t
        cams[name] = {
            "intrinsics": cam.K.astype(np.float32),
            "extrinsics": E,
            "distortions": dist.astype(np.float32),
        }
        rh = poses[t][0].astype(np.float64)
        R = rotvec_to_rotmat(torch.as_tensor(rh)).numpy()
        # the project's body: world = R(v − J0b) + J0b + trans, J0b = rest[0] − offset;
        # the subject's pelvis J0s = rest[0] goes to the same place: R·J0s + Th
        j0b = body.rest_joints[0].double().numpy()
        th = trans[t] + j0b - R @ rest[0]
        smpl_pose = poses[t].astype(np.float64).copy()
        smpl_pose[0] = 0.0
        joints = body.forward(torch.as_tensor(smpl_pose)[None]).joints[0].double().numpy()
        infos[name] = {
            "Rh": rh.astype(np.float32),
            "Th": th.astype(np.float32),
            "poses": smpl_pose.reshape(72).astype(np.float32),
            "joints": joints,
            "tpose_joints": rest,
        }
    for fname, data in (("cameras.pkl", cams), ("mesh_infos.pkl", infos)):
        with open(root / fname, "wb") as fh:
            pickle.dump(data, fh)
    return root
