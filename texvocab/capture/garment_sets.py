"""The garment set of ``texvocab synth --garment NAME``.

- ``painted`` (default): the tracking mesh itself with painted, albedo-only folds; the
  capture ``texvocab synth`` has always made, reproduced bit for bit.
- ``hoodie``: a loose top 2.5 cm off the body on the chest and back, widening to 6 cm at
  the hem and at the cuffs, over trousers 1.2 cm off the legs.
- ``wide-trousers``: a close shirt (1 cm) over wide trousers, 1.5 cm at the hips flaring
  to 10 cm at the ankle hem (half that on the inner side of each leg, so the legs' cloth
  stays apart).
- ``loose``: the hoodie over the wide trousers.

Every garment but ``painted`` is geometry (:class:`~texvocab.capture.garment_mesh.
ClothMesh`): folds are rounded ridges, lit, on each part's own skin, driven by the same
joints as the painted ones (:data:`~texvocab.capture.garment.FOLD_SOURCES`) with crease
spacing x ``fold_spacing`` and reach x ``fold_reach`` (loose cloth folds wider and over
more of the limb), their strength growing as the square root of the bend (buckling), and
``fold_depth`` high on cloth 3 cm off the body (x 0.5 on close cloth, up to x 2 at a 6 cm
hem). The strength was chosen so that ``bench/pose_signal.py``'s rest-pose column is near
a trained avatar's error (docs/results.md); deeper ridges look like accordions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from texvocab.body.poses import J
from texvocab.errors import AssetError

SHIRT, PANTS = 2, 3  # texvocab.capture.garment.regions


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def hoodie_top(p: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """(N,) thickness (m) of a loose top at rest points (N, 3): 2.5 cm on the torso, up
    to 6 cm at the hem (the last 15 cm above it) and along the sleeves, gathered back to
    1.5 cm in a cuff band over the last 4 cm before the wrist."""
    hem_y = joints[J["pelvis"], 1] + 0.04
    hem = _smoothstep((hem_y + 0.15 - p[:, 1]) / 0.15)
    shoulder_x, wrist_x = abs(joints[J["left_shoulder"], 0]), abs(joints[J["left_wrist"], 0]) - 0.03
    sleeve = _smoothstep((np.abs(p[:, 0]) - shoulder_x) / (wrist_x - shoulder_x))
    cuff = _smoothstep((np.abs(p[:, 0]) - (wrist_x - 0.06)) / 0.04)
    return (0.025 + 0.035 * np.maximum(hem, sleeve)) * (1 - cuff) + 0.015 * cuff


def close_top(p: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """(N,) a shirt 1 cm off the body."""
    return np.full(len(p), 0.01)


def close_trousers(p: np.ndarray, n: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """(N,) trousers 1.2 cm off the legs."""
    return np.full(len(p), 0.012)


def wide_trousers(p: np.ndarray, n: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """(N,) 1.5 cm at the hips flaring to 10 cm at the ankle; where the normal faces the
    other leg (n_x against the leg's side) at most half as much."""
    hip_y, ankle_y = joints[J["left_hip"], 1], joints[J["left_ankle"], 1] + 0.03
    down = np.clip((hip_y - p[:, 1]) / (hip_y - ankle_y), 0, 1)
    t = 0.015 + 0.085 * down**1.5
    inner = np.clip(-n[:, 0] * np.sign(p[:, 0]), 0, 1)
    return t * (1 - 0.5 * inner)


@dataclass(frozen=True)
class GarmentSpec:
    """A garment with geometry: how far each region's cloth lies off the body, how
    high its fold ridges are, how finely the body mesh is subdivided, and how many
    neighbour-averaging passes blend the cloth's skinning weights."""

    name: str
    top: object  # (points (N, 3), joints (24, 3)) -> (N,) metres
    bottom: object  # (points (N, 3), normals (N, 3), joints (24, 3)) -> (N,) metres
    fold_depth: float = 0.02
    fold_spacing: float = 1.6  # x each fold source's crease spacing
    fold_reach: float = 2.0  # x each fold source's reach along its bone (garment.FOLD_SOURCES)
    subdivisions: int = 2
    weight_smoothing: int = 8

    def thickness(self, p: np.ndarray, n: np.ndarray, region: np.ndarray, joints: np.ndarray) -> np.ndarray:
        """(N,) rest-pose distance of the cloth from the body (0 on skin, hair, shoes)."""
        t = np.zeros(len(p))
        t[region == SHIRT] = self.top(p, joints)[region == SHIRT]
        t[region == PANTS] = self.bottom(p, n, joints)[region == PANTS]
        return t


#: Garments with geometry by name; ``painted`` (the default) is the albedo-only garment.
GARMENTS: dict[str, GarmentSpec] = {
    "hoodie": GarmentSpec("hoodie", hoodie_top, close_trousers),
    "wide-trousers": GarmentSpec("wide-trousers", close_top, wide_trousers),
    "loose": GarmentSpec("loose", hoodie_top, wide_trousers),
}
DEFAULT_GARMENT = "painted"
GARMENT_NAMES = (DEFAULT_GARMENT, *GARMENTS)


def garment_spec(name: str) -> GarmentSpec | None:
    """The spec of a garment name; None for ``painted``; AssetError for an unknown name."""
    if name == DEFAULT_GARMENT:
        return None
    if name not in GARMENTS:
        raise AssetError(f"unknown garment {name!r}; expected one of {GARMENT_NAMES}")
    return GARMENTS[name]
