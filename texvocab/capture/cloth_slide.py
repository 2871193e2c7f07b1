"""Cloth that slides over the body with pose (``texvocab synth --cloth-slide M``).

On a real capture the cloth does not stay at one place on the body: a sleeve rides up
the forearm as the elbow bends, trouser legs ride up the shin as the knee bends, a top
rides up the back as the torso bends and lags behind it as the torso twists. So a body
texel shows another piece of cloth a few frames later (docs/results.md, "What the texture
path can give on 387"). This module gives the synthetic garments that behaviour with
ground truth: the garment's pattern is painted at rest points moved by a displacement
that each part's own joints drive, so the appearance of a texel is a function of its
part's pose, which a body-part vocabulary can select and a canonical texture cannot hold.

Four kinds of slide, each on its own part's cloth, each growing with the part's bend
``min(angle / 90°, 1.2)`` and ramping from 0 where the cloth is held (shoulder seam, hip,
chest) to the full ``metres`` at the free end (cuff, ankle hem, top's hem):

- each sleeve along its arm, towards the shoulder, and as much round the arm, with the
  elbow's bend;
- each trouser leg up the leg with the knee's bend;
- the top up the body with the torso's bend (spine1-spine3), and round the spine by
  ``metres`` of arc at the hem with its twist, against the twist.

Regions (skin, shirt, trousers) stay where they are: only the pattern inside them moves.
"""

from __future__ import annotations

import numpy as np

from texvocab.body.poses import J
from texvocab.geometry.rotations import bend_twist


def _ramp(x: np.ndarray) -> np.ndarray:
    return np.clip(x, 0.0, 1.0)


def bend_and_twist(pose: np.ndarray, joints: tuple[int, ...], bone: np.ndarray) -> tuple[float, float]:
    bend, twist, _ = bend_twist(pose[list(joints)], bone / np.linalg.norm(bone))
    return bend, twist


def _strength(angle: float) -> float:
    # below a milliradian (rounding at the rest pose) nothing slides, as no fold forms
    return 0.0 if angle < 1e-3 else float(np.clip(angle / (np.pi / 2), 0.0, 1.2))


def slide_offsets(
    points: np.ndarray, region: np.ndarray, joints: np.ndarray, pose: np.ndarray, metres: float
) -> np.ndarray:
    """(N, 3) how far the cloth at rest points (N, 3) has slid at ``pose`` (24, 3)
    axis-angle, in the rest frame; ``region`` (N,) per point (2 shirt, 3 trousers: see
    :func:`texvocab.capture.garment.regions`), ``joints`` (24, 3) the rest joints. The
    pattern seen at a point ``p`` is the rest pattern at ``p - offset``."""
    off = np.zeros_like(points)
    if metres == 0:
        return off
    x, y = points[:, 0], points[:, 1]
    shirt, pants = region == 2, region == 3
    shoulder_x = abs(joints[J["left_shoulder"], 0])
    for side in ("left", "right"):
        sign = np.sign(joints[J[f"{side}_shoulder"], 0])
        elbow, wrist = J[f"{side}_elbow"], J[f"{side}_wrist"]
        bend, _ = bend_and_twist(pose, (elbow,), joints[wrist] - joints[elbow])
        along = _ramp((sign * x - shoulder_x) / (abs(joints[wrist, 0]) - shoulder_x))
        sleeve = shirt & (sign * x > shoulder_x)
        amount = metres * _strength(bend) * along[sleeve]
        off[sleeve, 0] -= sign * amount
        # and it turns about the arm by as much arc, which the stripes round it show
        axis = joints[elbow]
        off[sleeve, 1:] += _turned(points[sleeve][:, 1:] - axis[1:], amount)
        hip, knee, ankle = J[f"{side}_hip"], J[f"{side}_knee"], J[f"{side}_ankle"]
        bend, _ = bend_and_twist(pose, (knee,), joints[ankle] - joints[knee])
        down = _ramp((joints[hip, 1] - y) / (joints[hip, 1] - joints[ankle, 1]))
        leg = pants & (np.sign(x) == np.sign(joints[hip, 0]))
        off[leg, 1] += metres * _strength(bend) * down[leg]
    chain = (J["spine1"], J["spine2"], J["spine3"])
    spine = joints[J["neck"]] - joints[J["spine1"]]
    bend, twist = bend_and_twist(pose, chain, spine / np.linalg.norm(spine))
    hem_y, chest_y = joints[J["pelvis"], 1] + 0.04, joints[J["spine3"], 1]
    up = _ramp((chest_y - y) / (chest_y - hem_y))
    torso = shirt & (np.abs(x) <= shoulder_x)
    off[torso, 1] += metres * _strength(bend) * up[torso]
    # the hem lags the twist: the pattern turns about the spine, against the twist
    centre = joints[J["spine2"]][[0, 2]]
    arc = -np.sign(twist) * metres * _strength(abs(twist)) * up[torso]
    off[np.ix_(torso, [0, 2])] += _turned(points[torso][:, [0, 2]] - centre, arc)
    return off


def _turned(rel: np.ndarray, arc: np.ndarray) -> np.ndarray:
    """(N, 2) how far points (N, 2) relative to an axis move when turned about it by
    ``arc`` (N,) metres of arc (at least 5 cm of radius, so the axis does not spin)."""
    angle = arc / np.maximum(np.linalg.norm(rel, axis=1), 0.05)
    c, s = np.cos(angle), np.sin(angle)
    turned = np.stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]], 1)
    return turned - rel
