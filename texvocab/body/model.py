"""BodyModel: an SMPL-compatible skinned body built from arrays only.

Loaders (``smpl_io``, ``default``) turn files into arrays; the model never reads files.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from texvocab.body.lbs import lbs
from texvocab.body.parts import JOINT_NAMES
from texvocab.errors import AssetError, PoseError

POSE_ANGLE_LIMIT = 4 * np.pi  # rad per joint: axis-angle beyond two full turns is refused
TRANS_LIMIT = 1e4  # metres: a root translation beyond this is not a person in a capture


@dataclass
class BodyOutput:
    """Result of :meth:`BodyModel.forward` (all in world space, metres)."""

    vertices: torch.Tensor  # (B, V, 3)
    joints: torch.Tensor  # (B, J, 3)
    transforms: torch.Tensor  # (B, J, 4, 4) rest -> posed, root translation included


def _as_tensor(name: str, value, dtype: torch.dtype) -> torch.Tensor:
    arr = np.asarray(value)
    if arr.dtype.kind not in "biuf":
        raise AssetError(f"{name}: expected a numeric array, got dtype {arr.dtype}")
    return torch.as_tensor(arr.astype(np.float64), dtype=dtype)


class BodyModel:
    """Skinned body with SMPL's 24-joint tree.

    Args:
        v_template: (V, 3) rest vertices.
        faces: (F, 3) triangle vertex indices.
        weights: (V, J) skinning weights.
        parents: (J,) parent index per joint, -1 for the root.
        joints: (J, 3) rest joints, used when ``J_regressor`` is absent.
        J_regressor: (J, V) joint regressor (dense or scipy sparse); joints follow shape.
        vt: (T, 2) UV coordinates (OBJ convention, origin bottom-left); ft: (F, 3).
        shapedirs: (V, 3, S) shape blend shapes; posedirs: (V, 3, (J-1)*9) pose correctives.
        name: where the arrays came from (for messages).
    """

    def __init__(
        self,
        v_template,
        faces,
        weights,
        parents,
        joints=None,
        J_regressor=None,
        vt=None,
        ft=None,
        shapedirs=None,
        posedirs=None,
        name: str = "body",
        dtype: torch.dtype = torch.float32,
    ):
        self.name = name
        self.dtype = dtype
        self.v_template = _as_tensor("v_template", v_template, dtype)
        num_verts = self.v_template.shape[0]
        self.faces = torch.as_tensor(np.asarray(faces, dtype=np.int64))
        self.weights = _as_tensor("weights", weights, dtype)
        self.parents = torch.as_tensor(np.asarray(parents, dtype=np.int64))
        self.num_joints = int(self.parents.shape[0])
        if J_regressor is not None:
            dense = J_regressor.toarray() if hasattr(J_regressor, "toarray") else J_regressor
            self.J_regressor = _as_tensor("J_regressor", dense, dtype)
        else:
            self.J_regressor = None
        if joints is None and self.J_regressor is None:
            raise AssetError(f"{name}: needs either 'joints' (J, 3) or 'J_regressor' (J, V)")
        self.rest_joints = (
            _as_tensor("joints", joints, dtype) if joints is not None else self.J_regressor @ self.v_template
        )
        self.vt = None if vt is None else _as_tensor("vt", vt, dtype)
        self.ft = None if ft is None else torch.as_tensor(np.asarray(ft, dtype=np.int64))
        self.shapedirs = None if shapedirs is None else _as_tensor("shapedirs", shapedirs, dtype)
        self.posedirs = None
        if posedirs is not None:
            pd = _as_tensor("posedirs", posedirs, dtype)
            self.posedirs = pd.reshape(num_verts * 3, -1).T.contiguous()  # (P, V*3)
        self._check_consistency(num_verts)

    def _check_consistency(self, num_verts: int) -> None:
        j = self.num_joints
        checks = [
            ("v_template", tuple(self.v_template.shape), (num_verts, 3)),
            ("weights", tuple(self.weights.shape), (num_verts, j)),
            ("joints", tuple(self.rest_joints.shape), (j, 3)),
            ("faces", tuple(self.faces.shape[1:]), (3,)),
        ]
        if self.ft is not None:
            checks.append(("ft", tuple(self.ft.shape), tuple(self.faces.shape)))
        for key, got, want in checks:
            if got != want:
                raise AssetError(f"{self.name}: '{key}' has shape {got}, expected {want}")
        if int(self.faces.max()) >= num_verts or int(self.faces.min()) < 0:
            raise AssetError(f"{self.name}: 'faces' index outside [0, {num_verts})")
        if self.parents[0] != -1 or any(int(self.parents[i]) >= i for i in range(1, j)):
            raise AssetError(f"{self.name}: 'parents' must have -1 at the root and parents[j] < j")
        for key in ("v_template", "weights", "rest_joints"):
            if not torch.isfinite(getattr(self, key)).all():
                raise AssetError(f"{self.name}: '{key}' contains non-finite values")

    @property
    def num_vertices(self) -> int:
        return int(self.v_template.shape[0])

    @property
    def num_betas(self) -> int:
        return 0 if self.shapedirs is None else int(self.shapedirs.shape[-1])

    def check_pose(self, pose: torch.Tensor, trans: torch.Tensor | None = None) -> None:
        """Raise :class:`PoseError` naming the joint when a pose is malformed or non-finite."""
        if pose.dim() != 3 or tuple(pose.shape[1:]) != (self.num_joints, 3):
            raise PoseError(
                f"pose has shape {tuple(pose.shape)}, expected (B, {self.num_joints}, 3) axis-angle per joint"
            )
        bad = ~torch.isfinite(pose).all(-1)
        if bad.any():
            b, j = (int(i) for i in bad.nonzero()[0])
            raise PoseError(f"pose[{b}, {j}] ({JOINT_NAMES[j]}) is not finite: {pose[b, j].tolist()}")
        bad = pose.norm(dim=-1) > POSE_ANGLE_LIMIT
        if bad.any():
            b, j = (int(i) for i in bad.nonzero()[0])
            raise PoseError(
                f"pose[{b}, {j}] ({JOINT_NAMES[j]}) turns {float(pose[b, j].norm()):.3g} "
                f"rad; expected axis-angle of at most 4π (two full turns)"
            )
        if trans is not None:
            if tuple(trans.shape) != (pose.shape[0], 3):
                raise PoseError(f"trans has shape {tuple(trans.shape)}, expected ({pose.shape[0]}, 3)")
            if not torch.isfinite(trans).all() or trans.abs().max() > TRANS_LIMIT:
                raise PoseError(
                    f"trans is not finite or beyond {TRANS_LIMIT:g} m: "
                    f"max |trans| = {float(trans.abs().max()):.3g}"
                )

    def shaped(self, betas: torch.Tensor | None, batch: int) -> tuple[torch.Tensor, torch.Tensor]:
        """Rest vertices (B, V, 3) and joints (B, J, 3) for shape coefficients (B, S)."""
        v = self.v_template.expand(batch, -1, -1)
        if betas is None:
            return v, self.rest_joints.expand(batch, -1, -1)
        if self.shapedirs is None:
            raise PoseError(f"{self.name} has no shape space (shapedirs); pass betas=None")
        if betas.dim() != 2 or betas.shape[0] != batch or betas.shape[1] > self.num_betas:
            raise PoseError(f"betas has shape {tuple(betas.shape)}, expected ({batch}, <= {self.num_betas})")
        if not torch.isfinite(betas).all():
            raise PoseError("betas is not finite")
        dirs = self.shapedirs[..., : betas.shape[1]]
        v = v + torch.einsum("bs,vcs->bvc", betas.to(self.dtype), dirs)
        if self.J_regressor is not None:
            joints = torch.einsum("jv,bvc->bjc", self.J_regressor, v)
        else:
            joints = self.rest_joints.expand(batch, -1, -1)
        return v, joints

    def forward(self, pose, trans=None, betas=None) -> BodyOutput:
        """Pose the body.

        Args:
            pose: (B, J, 3) axis-angle per joint (SMPL order), root orientation at joint 0.
            trans: (B, 3) root translation, or None for zero.
            betas: (B, S) shape coefficients, or None for the template shape.
        """
        pose = torch.as_tensor(pose, dtype=self.dtype)
        trans = None if trans is None else torch.as_tensor(trans, dtype=self.dtype)
        betas = None if betas is None else torch.as_tensor(betas, dtype=self.dtype)
        self.check_pose(pose, trans)
        batch = pose.shape[0]
        v_shaped, joints = self.shaped(betas, batch)
        verts, posed_joints, transforms = lbs(
            pose, v_shaped, joints, self.parents, self.weights, self.posedirs
        )
        if trans is not None:
            verts = verts + trans[:, None]
            posed_joints = posed_joints + trans[:, None]
            transforms = transforms.clone()
            transforms[..., :3, 3] += trans[:, None]
        return BodyOutput(verts, posed_joints, transforms)

    __call__ = forward
