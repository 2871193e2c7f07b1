"""Pose refinement: per-frame learnable corrections of a capture's recorded body poses.

A real capture's SMPL fit is centimetres and degrees off; every texture map and every
training ray then pairs the image with the wrong place on the body. As InstantAvatar,
GauHuman and 3DGS-Avatar do, each training frame t gets its own correction, trained with
the avatar: δθ_t (axis-angle added to the recorded rotations: the root's only, or every
joint's) and δT_t (added to the root translation). Held-out frames keep their recorded
poses (they have no images to train on), so refinement changes what the field learns, not
how it is queried.

How a correction reaches the field without re-posing and re-indexing the body every step:
the corrected body moves each bone j by B_j = A_j(θ+δθ, T+δT) A_j(θ, T)⁻¹ (posed space to
posed space). The field at the corrected pose, at a point x, is the field at the recorded
pose at x' = (Σ_j ω_j B_j)⁻¹ x, ω the skinning weights of x's closest body point, and a
viewing direction turned the same way: the field reads x' (its body distance to first
order, ∇d·(x' − x), its canonical point x_c exactly) and the gradients reach δθ, δT through
it. At δ = 0, x' = x: the field is the one without refinement. The texture feature is read
at x's UV (zeroth order: corrections are small against a texel's footprint on the body).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

POSE_REFINEMENTS = ("off", "root", "joints")


class PointWarp:
    """x → x' of one frame's correction (module docstring): ``bones`` (J, 4, 4) = B_j."""

    def __init__(self, bones: torch.Tensor):
        self.bones = bones

    def __call__(self, points: torch.Tensor, dirs: torch.Tensor, skin: torch.Tensor):
        """(x', d') (N, 3) each for points and unit dirs (N, 3) with skinning weights
        (N, J); points with no weights (outside the shell) take the root's bone."""
        b = self.bones.to(points.dtype)
        total = skin.sum(-1, keepdim=True)
        root = torch.zeros_like(skin)
        root[:, 0] = 1.0
        w = torch.where(total > 0, skin / total.clamp(min=1e-12), root)
        m = torch.einsum("nj,jrc->nrc", w, b)  # (N, 4, 4)
        rot, tr = m[:, :3, :3], m[:, :3, 3]
        x = torch.linalg.solve(rot, (points - tr).unsqueeze(-1)).squeeze(-1)
        d = torch.linalg.solve(rot, dirs.unsqueeze(-1)).squeeze(-1)
        return x, torch.nn.functional.normalize(d, dim=-1)


class PoseRefinement(nn.Module):
    """δθ_t, δT_t of ``num_frames`` training frames (zeros at the start), under ``mode``
    (:data:`POSE_REFINEMENTS` but ``off``): ``root`` corrects joint 0 and the translation,
    ``joints`` every joint and the translation.

    ``span`` frames share their corrections: the parameters sit on control frames 0,
    span, 2·span, … (and the last frame), and frame t's correction is the linear blend of
    its two neighbouring controls, so a step that draws frame t trains both. span 1 is
    one parameter pair per frame; a larger span trades temporal detail of the correction
    for span times as many draws of each parameter (a capture whose fit error varies
    slowly over its frames). An optimiser that skips parameters without a gradient (Adam
    with ``set_to_none``) moves only the controls a step drew."""

    def __init__(self, num_frames: int, num_joints: int, mode: str, span: int = 1):
        super().__init__()
        if mode not in POSE_REFINEMENTS[1:]:
            raise ValueError(f"pose refinement must be one of root, joints; got {mode!r}")
        if span < 1:
            raise ValueError(f"pose refinement span must be >= 1; got {span}")
        self.mode, self.span, self.num_frames = mode, int(span), int(num_frames)
        rows = 1 if mode == "root" else num_joints
        self.num_joints = num_joints
        controls = -(-(self.num_frames - 1) // self.span) + 1 if self.num_frames > 1 else 1
        self.rot = nn.ParameterList([nn.Parameter(torch.zeros(rows, 3)) for _ in range(controls)])
        self.trans = nn.ParameterList([nn.Parameter(torch.zeros(3)) for _ in range(controls)])

    def _blend(self, params: nn.ParameterList, t: int) -> torch.Tensor:
        """Frame t's value of per-control ``params``: the blend of its two controls."""
        i, r = divmod(int(t), self.span)
        if r == 0:
            return params[i]
        a = r / self.span
        return (1.0 - a) * params[i] + a * params[min(i + 1, len(params) - 1)]

    def delta(self, t: int) -> tuple[torch.Tensor, torch.Tensor]:
        """(δθ (J, 3), δT (3,)) of training frame t."""
        rot = self._blend(self.rot, t)
        if self.mode == "root":
            rot = torch.cat([rot, rot.new_zeros(self.num_joints - 1, 3)])
        return rot, self._blend(self.trans, t)

    def refined(self, t: int, pose: torch.Tensor, trans: torch.Tensor):
        """Frame t's refined pose (J, 3) and translation (3,) from its recorded ones."""
        rot, tr = self.delta(t)
        return pose.to(rot) + rot, trans.to(tr) + tr

    def warp(self, t: int, body, pose: torch.Tensor, trans: torch.Tensor, betas=None) -> PointWarp:
        """The point warp of frame t's correction (gradients reach its δθ_t, δT_t)."""
        pose = torch.as_tensor(pose, dtype=torch.float32).reshape(-1, 3)
        trans = torch.as_tensor(trans, dtype=torch.float32).reshape(3)
        new_pose, new_trans = self.refined(t, pose, trans)
        with torch.no_grad():
            old = body.forward(pose[None], trans[None], betas).transforms[0]
        new = body.forward(new_pose[None], new_trans[None], betas).transforms[0]
        return PointWarp(new @ torch.linalg.inv(old).to(new))

    def prior(self, t: int) -> torch.Tensor:
        """Σ δθ_t² + (δT_t / 0.1 m)² of frame t's correction: keeps it small where the
        images do not ask for it (10 cm of translation weighs as 1 rad of rotation)."""
        rot, tr = self._blend(self.rot, t), self._blend(self.trans, t)
        return (rot**2).sum() + ((tr / 0.1) ** 2).sum()

    def state(self) -> dict:
        """{"mode", "span", "rot" (T, rows, 3), "trans" (T, 3) per training frame, and
        "control_rot", "control_trans" (the parameters)} for a checkpoint."""
        with torch.no_grad():
            return {
                "mode": self.mode,
                "span": self.span,
                "rot": torch.stack([self._blend(self.rot, t).detach() for t in range(self.num_frames)]),
                "trans": torch.stack([self._blend(self.trans, t).detach() for t in range(self.num_frames)]),
                "control_rot": torch.stack([p.detach() for p in self.rot]),
                "control_trans": torch.stack([p.detach() for p in self.trans]),
            }

    def load(self, state: dict) -> None:
        """Back from :meth:`state` (a state without controls is one of span 1)."""
        rot, trans = state.get("control_rot", state["rot"]), state.get("control_trans", state["trans"])
        if int(state.get("span", 1)) != self.span or len(rot) != len(self.rot):
            raise ValueError(
                f"pose refinement state has span {state.get('span', 1)} and {len(rot)} controls; "
                f"this run has span {self.span} and {len(self.rot)}"
            )
        with torch.no_grad():
            for p, v in zip(self.rot, rot, strict=True):
                p.copy_(v)
            for p, v in zip(self.trans, trans, strict=True):
                p.copy_(v)


def refined_poses(state: dict, poses: np.ndarray, trans: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The refined poses (T, J, 3) and translations (T, 3) of a checkpoint's training frames
    from its ``pose_refinement`` state and the recorded ``poses`` (≥ T, J, 3), ``trans``."""
    rot = state["rot"].double().numpy()
    num = len(rot)
    out_pose = np.array(poses[:num], dtype=np.float64, copy=True)
    out_pose[:, : rot.shape[1]] += rot
    out_trans = np.asarray(trans[:num], dtype=np.float64) + state["trans"].double().numpy()
    return out_pose, out_trans
