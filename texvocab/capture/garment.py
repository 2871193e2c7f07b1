"""Procedural clothing for synthetic captures: a detailed garment albedo in UV space plus
pose-dependent folds whose position, shape and strength follow the joint rotations.

Everything is defined on the body's rest surface (each texel knows its rest 3D point and
skinning weights), so patterns are continuous across UV seams and folds sit at the right
place on the body: elbow flexion creases the inner elbow, knee flexion the back of the
knee, hip flexion the groin, shoulder raises the armpit, torso twist and bend make
diagonal folds on the shirt.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from texvocab.body.poses import J
from texvocab.capture.cloth_slide import slide_offsets
from texvocab.geometry.rotations import bend_twist
from texvocab.geometry.uv import texel_map

SKIN = np.array([0.86, 0.66, 0.53])
HAIR = np.array([0.16, 0.10, 0.07])
SHIRT = np.array([0.10, 0.45, 0.55])
SHIRT_LINE = np.array([0.95, 0.92, 0.80])
LOGO = np.array([0.85, 0.25, 0.15])
PANTS = np.array([0.16, 0.20, 0.38])
PANTS_LINE = np.array([0.70, 0.62, 0.30])
SHOE = np.array([0.08, 0.08, 0.09])
SOLE = np.array([0.92, 0.92, 0.92])


@dataclass
class FoldSource:
    """Creases caused by one joint (or a chain of joints) bending and twisting.

    ``joints`` are composed in order (the torso uses the three spine joints); the bone runs
    from ``joints[0]`` towards ``child``; creases appear within ``reach`` metres of
    ``joints[-1]`` along the bone, ``offset`` metres from it.
    """

    name: str
    joints: tuple[int, ...]
    child: int
    reach: float
    offset: float = 0.0
    spacing: float = 0.05


FOLD_SOURCES = (
    FoldSource("left_elbow", (J["left_elbow"],), J["left_wrist"], 0.11),
    FoldSource("right_elbow", (J["right_elbow"],), J["right_wrist"], 0.11),
    FoldSource("left_knee", (J["left_knee"],), J["left_ankle"], 0.10),
    FoldSource("right_knee", (J["right_knee"],), J["right_ankle"], 0.10),
    FoldSource("left_hip", (J["left_hip"],), J["left_knee"], 0.10, 0.06),
    FoldSource("right_hip", (J["right_hip"],), J["right_knee"], 0.10, 0.06),
    FoldSource("left_shoulder", (J["left_shoulder"],), J["left_elbow"], 0.09, 0.04),
    FoldSource("right_shoulder", (J["right_shoulder"],), J["right_elbow"], 0.09, 0.04),
    FoldSource("torso", (J["spine1"], J["spine2"], J["spine3"]), J["neck"], 0.22, 0.18, 0.07),
)


def _crease(x: np.ndarray, sharpness: int = 3) -> np.ndarray:
    """Thin periodic lines: 1 on the crease, 0 between (period 1)."""
    return np.maximum(0.0, np.cos(2 * np.pi * x)) ** sharpness


def regions(points: np.ndarray, weights: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """Per rest point (N, 3) with skinning weights (N, J), given the rest joints (J, 3):
    0 skin, 1 hair, 2 shirt, 3 pants, 4 shoe."""
    p, jnt = points, joints
    dom = weights.argmax(1)
    region = np.full(len(p), 2)
    legs = np.isin(
        dom,
        [
            J["left_hip"],
            J["right_hip"],
            J["left_knee"],
            J["right_knee"],
            J["left_ankle"],
            J["right_ankle"],
        ],
    )
    region[legs | (p[:, 1] < jnt[J["pelvis"], 1] + 0.04)] = 3
    ankle_y = jnt[J["left_ankle"], 1]
    region[np.isin(dom, [J["left_foot"], J["right_foot"]]) | (p[:, 1] < ankle_y + 0.03)] = 4
    wrist_x = abs(jnt[J["left_wrist"], 0])  # long sleeves: folds form on fabric
    arm_skin = (np.abs(p[:, 0]) > wrist_x - 0.03) & (p[:, 1] > jnt[J["pelvis"], 1])
    region[arm_skin] = 0
    head = np.isin(dom, [J["head"], J["neck"]]) & (p[:, 1] > jnt[J["neck"], 1] - 0.02)
    region[head] = 0
    hair = head & (
        (p[:, 1] > jnt[J["head"], 1] + 0.06)
        | ((p[:, 2] < jnt[J["head"], 2] - 0.02) & (p[:, 1] > jnt[J["head"], 1] - 0.04))
    )
    region[hair] = 1
    return region


def fold_localities(points: np.ndarray, joints: np.ndarray, sources=FOLD_SOURCES) -> dict[str, tuple]:
    """Per fold source, which rest points (N, 3) lie near its joint and their bone
    coordinates; ``joints`` (24, 3) rest joints."""
    local = {s.name: _locality(points, joints, s) for s in sources}
    local["_count"] = (len(points),)
    local["_sources"] = tuple(sources)
    return local


def _locality(points: np.ndarray, joints: np.ndarray, s: FoldSource):
    pivot = joints[s.joints[-1]]
    bone = joints[s.child] - joints[s.joints[0]]
    bone /= np.linalg.norm(bone)
    rel = points - pivot
    along = rel @ bone - s.offset
    radial = rel - np.outer(rel @ bone + 0.0, bone)
    dist = np.linalg.norm(radial, axis=1)
    near = np.nonzero((np.abs(along) < 2.0 * s.reach) & (dist < 0.2))[0]
    ref = np.cross(bone, [0.0, 0.0, 1.0] if abs(bone[2]) < 0.9 else [1.0, 0.0, 0.0])
    ref /= np.linalg.norm(ref)
    rad = radial[near] / np.maximum(dist[near], 1e-9)[:, None]
    azim = np.arctan2(rad @ np.cross(bone, ref), rad @ ref)
    return near, bone, along[near], rad, azim


def fold_intensity(
    local: dict[str, tuple],
    pose,
    skin: dict[str, np.ndarray] | None = None,
    sharpness: int = 3,
    buckling: bool = False,
) -> np.ndarray:
    """(N,) crease intensity (>= 0, not clipped) at the points of ``local``
    (:func:`fold_localities`) for a pose (24, 3) axis-angle. ``skin``: per source, a factor
    (N,) in [0, 1] that keeps its creases on its own part's surface (None: no limit);
    ``sharpness``: crease profile ``max(0, cos) ** sharpness`` (3: thin painted lines, 1:
    the rounded ridges of cloth geometry); ``buckling``: crease strength grows as the
    square root of the bend and twist angles, as the amplitude of buckled cloth grows with
    the square root of its compression (False: linearly, as painted folds)."""
    pose = torch.as_tensor(np.asarray(pose, dtype=np.float64))
    total = np.zeros(local["_count"][0])
    for s in local["_sources"]:
        near, bone, along, rad, azim = local[s.name]
        bend, twist, moved = bend_twist(pose[list(s.joints)], bone)
        cos_b = float(np.clip(moved @ bone, -1, 1))
        fold = np.zeros(len(near))
        if bend > 1e-3:
            n = moved - cos_b * bone
            n /= np.linalg.norm(n)
            inner = 0.3 + 0.7 * np.clip(rad @ n, 0, 1)  # sleeves bunch all round, most inside
            spacing = s.spacing * (1.0 - 0.35 * min(bend / np.pi, 1.0))
            centre = 0.25 * s.reach * np.sin(bend)  # creases gather toward the bend
            env = np.exp(-0.5 * ((along - centre) / s.reach) ** 2)
            strength = np.clip(bend / (np.pi / 2), 0, 1.2)
            strength = np.sqrt(strength) if buckling else strength
            wave = _crease(along / spacing + 0.15 * np.sin(azim * 2 + bend), sharpness)
            fold += strength * env * inner * wave
        if abs(twist) > 1e-3:
            env = np.exp(-0.5 * (along / (1.3 * s.reach)) ** 2)
            helix = _crease(along / (1.4 * s.spacing) + np.sign(twist) * 2 * azim / (2 * np.pi), sharpness)
            twisted = np.clip(abs(twist) / (np.pi / 6), 0, 1)
            fold += (np.sqrt(twisted) if buckling else twisted) * env * helix * 0.8
        if skin is not None:
            fold = fold * skin[s.name][near]
        total[near] = np.maximum(total[near], fold)
    return total


class Garment:
    """Texture generator for one body.

    Args:
        body: a :class:`~texvocab.body.BodyModel` with UVs (``vt``, ``ft``).
        size: texture size in pixels (square).
    """

    def __init__(self, body, size: int = 1024):
        if body.vt is None:
            raise ValueError(f"{body.name} has no UVs; synthetic clothing needs vt/ft")
        self.size = size
        self.joints = body.rest_joints.double().numpy()
        self.texels = texel_map(body, size)
        self.covered = self.texels.covered
        faces = body.faces.numpy()
        self.points = self.texels.points(body.v_template.double().numpy(), faces)
        self.weights = self.texels.interpolate(body.weights.double().numpy(), faces)
        # per texel, fixed at rest: 0 skin, 1 hair, 2 shirt, 3 pants, 4 shoe
        self.region = regions(self.points, self.weights, self.joints)
        self.albedo = self._paint_albedo()
        self._local = fold_localities(self.points, self.joints)

    # -- static albedo -------------------------------------------------------------------
    def _to_image(self, values: np.ndarray) -> np.ndarray:
        # Uncovered texels copy their nearest covered texel so bilinear lookups at UV seams
        # never blend in a background colour.
        return self.texels.to_image(values.astype(np.float64))

    def _paint_albedo(self, pattern_points: np.ndarray | None = None) -> np.ndarray:
        """(size, size, 3) the static albedo; ``pattern_points`` (N, 3), where each
        texel's pattern is read (default its rest point; regions stay at the rest points)."""
        p, jnt = (self.points if pattern_points is None else pattern_points), self.joints
        region = self.region
        col = np.zeros((len(p), 3))
        x, y, z = p.T
        # skin with faint mottling; hair with strands
        col[region == 0] = SKIN * (0.97 + 0.03 * np.sin(40 * x + 23 * y + 31 * z))[region == 0, None]
        strands = 0.8 + 0.4 * _crease(x / 0.006 + 3 * z, 2)
        col[region == 1] = HAIR * strands[region == 1, None]
        # shirt: sharp horizontal stripes, fine vertical pinstripes, a chest checker logo
        shirt = region == 2
        stripes = (np.mod(y / 0.045, 1.0) < 0.18).astype(float)
        azim = np.arctan2(z - jnt[J["spine2"], 2], x)
        pins = (np.mod(azim / (2 * np.pi) * 90, 1.0) < 0.12).astype(float) * (np.abs(x) < 0.25)
        c = SHIRT * (1 - 0.25 * pins)[:, None]
        c = c * (1 - stripes[:, None]) + SHIRT_LINE * stripes[:, None]
        chest = (
            (z > jnt[J["spine3"], 2]) & (np.abs(x - 0.08) < 0.06) & (np.abs(y - jnt[J["spine3"], 1]) < 0.06)
        )
        checker = (np.floor((x - 0.02) / 0.015) + np.floor(y / 0.015)) % 2 == 0
        c[chest & checker] = LOGO
        col[shirt] = c[shirt]
        # pants: plaid lines in height and around each leg, a bright seam stripe
        pants = region == 3
        leg_x = np.where(x > 0, jnt[J["left_knee"], 0], jnt[J["right_knee"], 0])
        around = np.arctan2(z - jnt[J["left_knee"], 2], x - leg_x) / (2 * np.pi)
        plaid = np.maximum(np.mod(y / 0.05, 1.0) < 0.1, np.mod(around * 16, 1.0) < 0.1)
        seam = np.abs(np.abs(around) - 0.5) < 0.02
        pc = PANTS * (1 + 0.12 * _crease((x + y) / 0.01, 2))[:, None]
        pc[plaid] = 0.5 * PANTS + 0.5 * PANTS_LINE
        pc[seam] = PANTS_LINE
        col[pants] = pc[pants]
        shoe = region == 4
        sole = y < y.min() + 0.025
        col[shoe] = SHOE
        col[shoe & sole] = SOLE
        return self._to_image(np.clip(col, 0, 1)).astype(np.float32)

    def albedo_at(self, pose, slide: float) -> np.ndarray:
        """(size, size, 3) the albedo with the cloth slid ``slide`` metres at full bend
        for a pose (24, 3) (:mod:`texvocab.capture.cloth_slide`); the static albedo at 0."""
        if slide == 0:
            return self.albedo
        offsets = slide_offsets(self.points, self.region, self.joints, np.asarray(pose, np.float64), slide)
        return self._paint_albedo(self.points - offsets)

    # -- pose-dependent folds ----------------------------------------------------------
    def fold_map(self, pose) -> np.ndarray:
        """(size, size) crease intensity in [0, 1] for a pose (24, 3) axis-angle."""
        return self._to_image(np.clip(fold_intensity(self._local, pose), 0, 1)).astype(np.float32)

    def texture(self, pose, slide: float = 0.0) -> np.ndarray:
        """(size, size, 3) float32 albedo with the pose's folds (row 0 = v = 1), its
        pattern slid ``slide`` metres at full bend (:meth:`albedo_at`)."""
        folds = self.fold_map(pose)[..., None]
        return np.clip(self.albedo_at(pose, slide) * (1.0 - 0.75 * folds), 0, 1)
