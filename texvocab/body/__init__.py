"""Body model: arrays -> posed vertices/joints (LBS), SMPL loader, default body and its
fit to a subject's rest joints, parts."""

from texvocab.body.default import default_body
from texvocab.body.fit import fit_rest_joints
from texvocab.body.model import BodyModel, BodyOutput
from texvocab.body.parts import BODY_PARTS, JOINT_NAMES, body_parts, part_attention
from texvocab.body.smpl_io import load_smpl


def load_body(smpl: str | None = None) -> BodyModel:
    """The user's SMPL model when ``smpl`` (file or folder) is given, else the default body."""
    return default_body() if smpl is None else load_smpl(smpl)


__all__ = [
    "BODY_PARTS",
    "JOINT_NAMES",
    "BodyModel",
    "BodyOutput",
    "body_parts",
    "default_body",
    "fit_rest_joints",
    "load_body",
    "load_smpl",
    "part_attention",
]
