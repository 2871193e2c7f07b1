"""The SMPL rest joints of an SMPL-X subject (THUman4.0's fits are SMPL-X).

SMPL-X betas live in SMPL-X's shape space, not SMPL's: fed into SMPL's blend shapes they
give another body. The subject's rest joints do carry over: SMPL-X and SMPL share body
joints 0–21 (pelvis to wrists), so with the user's SMPL-X model file the betas give the
subject's rest joints, and the capture's body is fitted to those as to HumanNeRF's
``tpose_joints`` (:func:`texvocab.capture.subject.fit_subject_body`). SMPL's hand joints
22–23 sit at the base of the middle finger, which SMPL-X has as joints 28 (left) and
43 (right); a regressor with fewer joints places them at the wrist plus the body's own
wrist-to-hand bone.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from texvocab.errors import AssetError
from texvocab.io.safe_pickle import read_npz, read_pickle
from texvocab.io.spec import require_valid, spec_ref

BODY_JOINTS = 22  # SMPL-X joints 0-21 are SMPL's
HAND_JOINTS = {22: 28, 23: 43}  # SMPL hand joint -> SMPL-X middle-finger base


def read_smplx_model(path: str | Path) -> dict:
    """The arrays of an SMPL-X model file (.npz or .pkl), checked against its spec."""
    path = Path(path).expanduser()
    if not path.is_file():
        raise AssetError(f"SMPL-X model file not found: {path}; see {spec_ref('smplx_model')}")
    if path.suffix == ".npz":
        arrays = read_npz(path, "SMPL-X model file")
    elif path.suffix == ".pkl":
        arrays = read_pickle(path, "SMPL-X pickle")
    else:
        raise AssetError(f"{path}: expected an SMPL-X model .npz or .pkl; see {spec_ref('smplx_model')}")
    require_valid(arrays, "smplx_model", str(path))
    reg = arrays["J_regressor"]
    if reg.shape[0] < BODY_JOINTS:
        raise AssetError(f"{path}: J_regressor has {reg.shape[0]} joints; expected >= {BODY_JOINTS}")
    return arrays


def smplx_rest_joints(arrays: dict, betas: np.ndarray, body_rest_joints: np.ndarray) -> np.ndarray:
    """(24, 3) SMPL-ordered rest joints of the SMPL-X body with ``betas`` (S,).

    ``body_rest_joints`` (24, 3): the capture body's own, whose wrist-to-hand bones place
    joints 22-23 when the regressor has no finger joints."""
    v = np.asarray(arrays["v_template"], np.float64)
    dirs = np.asarray(arrays["shapedirs"], np.float64)
    b = np.asarray(betas, np.float64).reshape(-1)[: dirs.shape[2]]
    v = v + np.einsum("vcs,s->vc", dirs[..., : len(b)], b)
    reg = arrays["J_regressor"]
    joints = np.asarray(reg @ v) if hasattr(reg, "tocsc") else np.asarray(reg, np.float64) @ v
    rest = np.asarray(body_rest_joints, np.float64)
    out = np.zeros((24, 3))
    out[:BODY_JOINTS] = joints[:BODY_JOINTS]
    for smpl, smplx in HAND_JOINTS.items():
        wrist = smpl - 2  # SMPL: 20/21 wrists, 22/23 hands
        if len(joints) > smplx:
            out[smpl] = joints[smplx]
        else:
            out[smpl] = out[wrist] + (rest[smpl] - rest[wrist])
    return out
