"""Fit a body to a subject's rest skeleton: when a capture gives the subject's SMPL rest
joints (HumanNeRF's ``tpose_joints``) but no SMPL files give its exact body, the embedded
default body takes those joints as its own and its surface follows them.

The surface moves by a displacement field that lives on the skeleton (a rest-to-rest
deformation, no pose involved). Each joint j has a *handle*, a segment with a
displacement at each end, and a rest vertex v moves by its skinning-weighted blend of
the handles::

    v' = v + sum_j w_vj * handle_j(v),    handle_j(v) = (1 - tau) * alpha_j + tau * beta_j,
    tau = clamp((v - a_j) . (b_j - a_j) / |b_j - a_j|^2, 0, 1)

- a joint with one child c (a limb bone): the segment J_j -> J_c, moving by base_j at
  J_j and by the child's displacement at J_c. Along a bone the displacement is linear,
  so a limb stretches uniformly along its bone by the bone's length ratio and its cross
  sections keep their shape (no thickening, no shear where the bone keeps its direction;
  where it turns a little, the cross sections shift in line with it);
- the trunk (pelvis, spine1, spine2, spine3): one segment pelvis -> neck. Rigs place the
  spine's interior joints by convention (SMPL's spine3 sits 6.4 cm lower and 4.4 cm
  further forward than the default body's against ZJU-MoCap 387's rest joints), so the
  torso's surface follows the trunk's ends only; following each spine joint folds the
  chest;
- leaves (head, hands, feet): a point moving by base_j;
- base_j is the parent's handle evaluated at J_j: along a limb the joint's own
  displacement, and where a branch leaves the trunk (hips, collars, neck) the trunk's
  surface there, so every region starts where its neighbour ends (a continuous field:
  blended by smooth weights it folds nothing; a hip joint placed 8 cm lower by another
  rig's convention re-rigs the thigh instead of dragging the crotch down).

The rest joints become the given ones exactly; faces, UVs and skinning weights are kept.
A joint regressor, if the body has one, is re-weighted on each row's own vertices (rows
keep their sums) so it regresses the given joints from the fitted template. Shape and
pose blend shapes are offsets in the rest frame and are kept as they are.

A body with a shape space (the user's SMPL files) need not be deformed at all: rest joints
are linear in its shape coefficients, so :func:`betas_from_rest_joints` recovers the betas
that give them (exactly, when the joints came from the same model).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from texvocab.body.model import BodyModel
from texvocab.body.parts import JOINT_NAMES
from texvocab.errors import AssetError

log = logging.getLogger("texvocab")

TRUNK = (0, 3, 6, 9)  # pelvis, spine1, spine2, spine3: their surface follows pelvis -> neck
NECK = 12
MIN_BONE = 1e-3  # metres: a target bone shorter than this (where the body's is longer) is refused


@dataclass(frozen=True)
class Handle:
    """A joint's share of the rest-to-rest displacement field: the segment ``start`` ->
    ``end`` (3,) moving by ``move_start`` at its start and ``move_end`` at its end
    (linear between, constant beyond the ends); ``end`` None for a point."""

    start: np.ndarray
    end: np.ndarray | None
    move_start: np.ndarray
    move_end: np.ndarray | None = None

    def displacement(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) displacement of rest points (N, 3)."""
        if self.end is None:
            return np.broadcast_to(self.move_start, points.shape)
        bone = self.end - self.start
        length2 = float(bone @ bone)
        if length2 < 1e-12:
            return np.broadcast_to(0.5 * (self.move_start + self.move_end), points.shape)
        tau = np.clip((points - self.start) @ bone / length2, 0.0, 1.0)[:, None]
        return (1.0 - tau) * self.move_start + tau * self.move_end


def skeleton_handles(joints: np.ndarray, target: np.ndarray, parents: np.ndarray) -> list[Handle]:
    """One :class:`Handle` per joint (see the module docstring) for moving rest joints
    (J, 3) to target (J, 3) in a tree ``parents`` (J,) with SMPL's joint order."""
    moves = target - joints
    children = [[c for c in range(len(parents)) if parents[c] == j] for j in range(len(parents))]
    handles: list[Handle] = []
    for j, parent in enumerate(parents):
        if j in TRUNK:
            handles.append(Handle(joints[0], joints[NECK], moves[0], moves[NECK]))
            continue
        base = moves[j] if parent < 0 else handles[parent].displacement(joints[j][None])[0]
        if len(children[j]) == 1:
            c = children[j][0]
            handles.append(Handle(joints[j], joints[c], base, moves[c]))
        else:
            handles.append(Handle(joints[j], None, base))
    return handles


def surface_displacement(
    vertices: np.ndarray, weights: np.ndarray, joints: np.ndarray, target: np.ndarray, parents: np.ndarray
) -> np.ndarray:
    """(V, 3) displacement of rest vertices (V, 3) with skinning weights (V, J) when the
    rest joints (J, 3) move to target (J, 3)."""
    handles = skeleton_handles(joints, target, parents)
    out = np.zeros_like(vertices)
    for j, handle in enumerate(handles):
        used = weights[:, j] != 0
        if used.any():
            out[used] += weights[used, j : j + 1] * handle.displacement(vertices[used])
    return out


def refit_regressor(regressor: np.ndarray, vertices: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(J, V) joint regressor whose rows regress target (J, 3) from vertices (V, 3): each
    row changes as little as it can (least squares) on the vertices it already uses,
    keeping its sum; a row whose vertices cannot reach its joint uses every vertex."""
    out = regressor.copy()
    for j, row in enumerate(regressor):
        for support in (np.nonzero(row)[0], np.arange(len(row))):
            a = np.vstack([np.ones(len(support)), vertices[support].T])  # (4, S)
            want = np.concatenate([[row.sum()], target[j]])
            new = row[support] + np.linalg.pinv(a) @ (want - a @ row[support])
            if np.abs(a @ new - want).max() < 1e-9:
                out[j] = 0.0
                out[j, support] = new
                break
        else:
            raise AssetError(
                f"joint regressor row {j} ({JOINT_NAMES[j]}) cannot regress "
                "its target joint from the fitted template"
            )
    return out


def bone_changes(joints: np.ndarray, target: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """(J,) change of each bone's length (joint to its parent), metres; 0 at the root."""
    out = np.zeros(len(parents))
    for j in range(1, len(parents)):
        out[j] = np.linalg.norm(target[j] - target[parents[j]]) - np.linalg.norm(
            joints[j] - joints[parents[j]]
        )
    return out


def _checked_target(body: BodyModel, rest_joints, source: str) -> np.ndarray:
    target = np.asarray(rest_joints, dtype=np.float64)
    if target.shape != (body.num_joints, 3):
        raise AssetError(f"{source}: rest joints have shape {target.shape}, expected ({body.num_joints}, 3)")
    if not np.isfinite(target).all():
        raise AssetError(f"{source}: rest joints are not finite")
    joints = body.rest_joints.double().numpy()
    parents = body.parents.numpy()
    for j in range(1, body.num_joints):
        new = np.linalg.norm(target[j] - target[parents[j]])
        if new < MIN_BONE <= np.linalg.norm(joints[j] - joints[parents[j]]):
            raise AssetError(
                f"{source}: the bone to joint {j} ({JOINT_NAMES[j]}) is "
                f"{new * 1000:.2g} mm long; expected at least {MIN_BONE * 1000:g} mm"
            )
    return target


def fit_rest_joints(body: BodyModel, rest_joints, source: str = "the capture's rest joints") -> BodyModel:
    """A new :class:`BodyModel` whose rest joints are ``rest_joints`` (J, 3) and whose rest
    surface follows them (module docstring); faces, UVs, weights and blend shapes kept.

    ``source`` names the joints in the log line and in errors (AssetError on a wrong
    shape, non-finite values or a collapsed bone).
    """
    target = _checked_target(body, rest_joints, source)
    joints = body.rest_joints.double().numpy()
    parents = body.parents.numpy()
    vertices = body.v_template.double().numpy()
    moved = vertices + surface_displacement(vertices, body.weights.double().numpy(), joints, target, parents)
    regressor = None
    if body.J_regressor is not None:
        regressor = refit_regressor(body.J_regressor.double().numpy(), moved, target)
    posedirs = None
    if body.posedirs is not None:  # stored (P, V * 3); the constructor takes (V, 3, P)
        posedirs = body.posedirs.T.reshape(body.num_vertices, 3, -1)
    fitted = BodyModel(
        v_template=moved,
        faces=body.faces,
        weights=body.weights.double().numpy(),
        parents=parents,
        joints=target,
        J_regressor=regressor,
        vt=None if body.vt is None else body.vt.numpy(),
        ft=None if body.ft is None else body.ft,
        shapedirs=None if body.shapedirs is None else body.shapedirs.double().numpy(),
        posedirs=None if posedirs is None else posedirs.double().numpy(),
        name=f"{body.name} fitted to {source}",
        dtype=body.dtype,
    )
    change = bone_changes(joints, target, parents)
    j = int(np.abs(change).argmax())
    log.info(
        "body: %s fitted to %s (largest bone change %+.1f cm at %s, surface moved up to %.1f cm)",
        body.name,
        source,
        100 * change[j],
        JOINT_NAMES[j],
        100 * float(np.linalg.norm(moved - vertices, axis=1).max()),
    )
    return fitted


def betas_from_rest_joints(
    body: BodyModel, rest_joints, num_betas: int | None = None
) -> tuple[np.ndarray, float]:
    """Shape coefficients (S,) whose rest joints J_reg (v_template + shapedirs · β) best
    match ``rest_joints`` (J, 3) in least squares, and the largest joint error left
    (metres). Needs a body with a joint regressor and a shape space."""
    if body.J_regressor is None or body.shapedirs is None:
        raise AssetError(f"{body.name} has no joint regressor and shape space to fit betas to")
    target = _checked_target(body, rest_joints, "rest joints")
    reg = body.J_regressor.double().numpy()
    dirs = body.shapedirs.double().numpy()[..., :num_betas]  # (V, 3, S)
    basis = np.einsum("jv,vcs->jcs", reg, dirs).reshape(-1, dirs.shape[-1])
    rest = reg @ body.v_template.double().numpy()
    betas = np.linalg.lstsq(basis, (target - rest).reshape(-1), rcond=None)[0]
    error = np.linalg.norm((basis @ betas).reshape(-1, 3) + rest - target, axis=1).max()
    return betas, float(error)
