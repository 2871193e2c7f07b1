"""What a real capture adds to the truth: imperfect body fits and camera imperfections.

Both are settings of :class:`~texvocab.capture.synth.SynthSettings`, off by default:

- ``fit_noise_deg`` / ``fit_noise_trans``: the capture records SMPL parameters that are
  the true ones plus noise, independent per frame: each joint's rotation (the root's
  too) composed with a random rotation of RMS angle ``fit_noise_deg`` degrees, the root
  translation moved by a random vector of RMS length ``fit_noise_trans`` metres. The
  images show the true poses; ``texvocab_synth.json`` keeps them (``true_poses``,
  ``true_trans``) for analysis only: no reader returns them.
- ``exposure_sd`` (stops), ``white_balance_sd`` (stops per channel): one gain per camera
  ``2 ** (exposure + white_balance[c])``, each drawn from N(0, sd); ``sensor_noise``:
  Gaussian noise of that standard deviation on every pixel, drawn per image. Applied to
  the written images only: ground truth rendered for new poses is clean.
"""

from __future__ import annotations

import numpy as np
import torch

from texvocab.geometry.rotations import quat_multiply, quat_to_rotvec, rotvec_to_quat

FIT_STREAM, CAMERA_STREAM = 1, 2  # independent random streams of one seed


def _rng(seed: int, stream: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence((int(seed), stream)))


def noisy_fit(
    poses: np.ndarray, trans: np.ndarray, deg: float, metres: float, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """Recorded (poses (T, 24, 3), trans (T, 3)) float32: the true ones plus noise of RMS
    rotation angle ``deg`` per joint and RMS translation length ``metres``."""
    rng = _rng(seed, FIT_STREAM)
    noise = rng.normal(0.0, np.radians(deg) / np.sqrt(3), poses.shape)
    q = quat_multiply(
        rotvec_to_quat(torch.as_tensor(noise, dtype=torch.float64)),
        rotvec_to_quat(torch.as_tensor(poses, dtype=torch.float64)),
    )
    rec = quat_to_rotvec(q).numpy()
    rec_trans = trans + rng.normal(0.0, metres / np.sqrt(3), trans.shape)
    return rec.astype(np.float32), rec_trans.astype(np.float32)


def rotation_error_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(...,) angle in degrees of the rotation between axis-angles ``a`` and ``b`` (..., 3)."""
    qa = rotvec_to_quat(torch.as_tensor(a, dtype=torch.float64))
    qb = rotvec_to_quat(torch.as_tensor(b, dtype=torch.float64))
    dot = (qa * qb).sum(-1).abs().clamp(max=1.0)
    return np.degrees(2 * torch.arccos(dot).numpy())


class CameraEffects:
    """Per-camera gains and sensor noise for ``num_cameras`` cameras (see module doc)."""

    def __init__(
        self, num_cameras: int, exposure_sd: float, white_balance_sd: float, noise: float, seed: int
    ):
        self._rng = _rng(seed, CAMERA_STREAM)
        exposure = self._rng.normal(0.0, exposure_sd, (num_cameras, 1))
        balance = self._rng.normal(0.0, white_balance_sd, (num_cameras, 3))
        self.gains = (2.0 ** (exposure + balance)).astype(np.float32)  # (C, 3)
        self.noise = float(noise)

    @property
    def active(self) -> bool:
        return bool(self.noise > 0 or np.any(self.gains != 1.0))

    def apply(self, camera: int, rgb: np.ndarray) -> np.ndarray:
        """(H, W, 3) float32 image as camera ``camera`` records it, clipped to [0, 1]."""
        out = rgb * self.gains[camera]
        if self.noise > 0:
            out = out + self._rng.normal(0.0, self.noise, rgb.shape).astype(np.float32)
        return np.clip(out, 0.0, 1.0).astype(np.float32)

    def to_dict(self) -> dict:
        return {"gains": self.gains.tolist(), "sensor_noise": self.noise}
