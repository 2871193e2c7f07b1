"""Colours of the 3D view's overlays: one per body part, and the novelty heat scale."""

from __future__ import annotations

import numpy as np

#: RGB in [0, 1] per body part (paper Table 1), distinct hues.
PART_COLORS: dict[str, tuple[float, float, float]] = {
    "main_body": (0.90, 0.80, 0.25),
    "left_leg": (0.20, 0.55, 0.95),
    "right_leg": (0.25, 0.80, 0.35),
    "left_arm": (0.95, 0.30, 0.25),
    "right_arm": (0.70, 0.35, 0.95),
}

#: Heat scale stops (t, RGB): t = novelty / novelty_scale, clipped to [0, 1].
HEAT_STOPS = np.array(
    [
        [0.00, 0.10, 0.20, 0.80],
        [0.25, 0.10, 0.75, 0.95],
        [0.50, 0.20, 0.85, 0.30],
        [0.75, 0.98, 0.85, 0.15],
        [1.00, 0.90, 0.12, 0.10],
    ]
)


def heat_color(t) -> np.ndarray:
    """(..., 3) heat colours of values t (...,) in [0, 1] (clipped): blue (a pose the
    vocabulary has seen) through green and yellow to red (far from every key)."""
    t = np.clip(np.asarray(t, dtype=np.float64), 0.0, 1.0)
    return np.stack([np.interp(t, HEAT_STOPS[:, 0], HEAT_STOPS[:, c]) for c in (1, 2, 3)], -1)
