"""Rotations: axis-angle vectors (rotvec), unit quaternions and rotation matrices.

Small pure functions named ``<src>_to_<dst>`` in the style of roma. Every function takes
any leading batch shape ``(...)`` (an empty batch too), keeps the dtype and device of its
input, and gives finite, accurate values *and* autograd gradients at the extreme angles
θ = 0 and θ = π (θ = 2π is the identity). Small angles use Taylor series behind the
"double where": the branch that is not selected only ever sees a harmless input, so it
cannot put NaN into the gradient.

Conventions (README, "Conventions"): quaternions are ``(w, x, y, z)``; the distance between two
rotations is ``1 - |q1·q2|``, which ignores the sign of either quaternion.
NumPy arrays are accepted (converted by :func:`as_tensor`); results are torch tensors.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

ArrayLike = Tensor | np.ndarray

# Below this squared angle (θ < 1e-3) the Taylor series to θ⁴ are exact in float64.
_SMALL = 1e-6


def as_tensor(x: ArrayLike, dtype: torch.dtype | None = None) -> Tensor:
    """Return ``x`` as a floating-point tensor, sharing memory with NumPy input if possible.

    Integer input becomes torch's default float dtype; float dtypes are kept.
    """
    t = torch.as_tensor(x, dtype=dtype)
    return t if t.is_floating_point() else t.to(torch.get_default_dtype())


def _check(x: ArrayLike, name: str, tail: tuple[int, ...]) -> Tensor:
    """Validate that ``x`` has shape ``(..., *tail)`` and finite entries; return a tensor."""
    x = as_tensor(x)
    if x.ndim < len(tail) or tuple(x.shape[x.ndim - len(tail) :]) != tail:
        expected = "(..., " + ", ".join(map(str, tail)) + ")"
        raise ValueError(f"{name}: expected shape {expected}, got {tuple(x.shape)}")
    if not bool(torch.isfinite(x).all()):
        raise ValueError(f"{name} must be finite, but it contains NaN or inf")
    return x


def _flatten(x: ArrayLike, name: str, tail: tuple[int, ...]) -> tuple[Tensor, torch.Size]:
    """Validate ``x`` of shape ``(..., *tail)``; return it as ``(N, *tail)`` and ``(...)``."""
    x = _check(x, name, tail)
    return x.reshape(-1, *tail), x.shape[: x.ndim - len(tail)]


def _flatten_pair(
    a: ArrayLike, b: ArrayLike, names: tuple[str, str], tail: tuple[int, ...]
) -> tuple[Tensor, Tensor, torch.Size]:
    """Validate and broadcast two ``(..., *tail)`` inputs; return both as ``(N, *tail)``."""
    a, b = torch.broadcast_tensors(_check(a, names[0], tail), _check(b, names[1], tail))
    return a.reshape(-1, *tail), b.reshape(-1, *tail), a.shape[: a.ndim - len(tail)]


# ----------------------------------------------------------------- cores on (N, k)


def _half_angle_terms(theta2: Tensor) -> tuple[Tensor, Tensor]:
    """``cos(θ/2)`` and ``sin(θ/2)/θ`` from ``θ²`` of shape ``(N,)``."""
    small = theta2 < _SMALL
    theta = torch.sqrt(torch.where(small, torch.ones_like(theta2), theta2))
    cos_half = torch.where(small, 1 - theta2 / 8 + theta2**2 / 384, torch.cos(theta / 2))
    sinc_half = torch.where(small, 0.5 - theta2 / 48 + theta2**2 / 3840, torch.sin(theta / 2) / theta)
    return cos_half, sinc_half


def _canonical(quat: Tensor) -> Tensor:
    """Flip ``(N, 4)`` quaternions to the hemisphere ``w >= 0``."""
    return torch.where(quat[:, :1] < 0, -quat, quat)


def _normalize(quat: Tensor) -> Tensor:
    return quat / torch.linalg.vector_norm(quat, dim=-1, keepdim=True)


def _rotvec_to_quat(rotvec: Tensor) -> Tensor:
    cos_half, sinc_half = _half_angle_terms((rotvec * rotvec).sum(-1))
    return torch.cat([cos_half[:, None], rotvec * sinc_half[:, None]], dim=-1)


def _quat_to_rotvec(quat: Tensor) -> Tensor:
    quat = _canonical(_normalize(quat))
    w, xyz = quat[:, 0], quat[:, 1:]
    s2 = (xyz * xyz).sum(-1)  # sin²(θ/2)
    small = s2 < _SMALL  # here w = cos(θ/2) ≈ 1
    w_safe = torch.where(small, w, torch.ones_like(w))
    t2 = s2 / w_safe**2  # tan²(θ/2)
    s = torch.sqrt(torch.where(small, torch.ones_like(s2), s2))
    # θ / sin(θ/2) = 2 atan(t) / (t w) with the series atan(t)/t = 1 - t²/3 + t⁴/5.
    scale = torch.where(small, 2 / w_safe * (1 - t2 / 3 + t2**2 / 5), 2 * torch.atan2(s, w) / s)
    return xyz * scale[:, None]


def _quat_to_rotmat(quat: Tensor) -> Tensor:
    w, x, y, z = quat.unbind(-1)
    s = 2 / (quat * quat).sum(-1)
    entries = [
        1 - s * (y * y + z * z), s * (x * y - z * w), s * (x * z + y * w),
        s * (x * y + z * w), 1 - s * (x * x + z * z), s * (y * z - x * w),
        s * (x * z - y * w), s * (y * z + x * w), 1 - s * (x * x + y * y),
    ]  # fmt: skip
    return torch.stack(entries, dim=-1).reshape(-1, 3, 3)


def _rotmat_to_quat(rotmat: Tensor) -> Tensor:
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotmat.reshape(-1, 9).unbind(-1)
    trace = r00 + r11 + r22
    # Shepperd: candidate i is 4 q_i q, exact for a rotation; take the one with largest |q_i|.
    candidates = torch.stack([
        torch.stack([1 + trace, r21 - r12, r02 - r20, r10 - r01], -1),
        torch.stack([r21 - r12, 1 + r00 - r11 - r22, r01 + r10, r02 + r20], -1),
        torch.stack([r02 - r20, r01 + r10, 1 - r00 + r11 - r22, r12 + r21], -1),
        torch.stack([r10 - r01, r02 + r20, r12 + r21, 1 - r00 - r11 + r22], -1),
    ], dim=1)  # fmt: skip
    choice = torch.stack([trace, r00, r11, r22], -1).argmax(-1)
    quat = candidates.gather(1, choice[:, None, None].expand(-1, 1, 4)).squeeze(1)
    return _canonical(_normalize(quat))


def _quat_distance(q1: Tensor, q2: Tensor) -> Tensor:
    return (1 - (q1 * q2).sum(-1).abs()).clamp_min(0)


# ----------------------------------------------------------------- public API


def rotvec_to_quat(rotvec: ArrayLike) -> Tensor:
    """Axis-angle ``(..., 3)`` to unit quaternion ``(..., 4)`` ``(cos θ/2, sin(θ/2) axis)``.

    Smooth in ``rotvec``; for θ > π the result has ``w < 0`` (same rotation as ``-q``).
    """
    rotvec, batch = _flatten(rotvec, "rotvec", (3,))
    return _rotvec_to_quat(rotvec).reshape(*batch, 4)


def quat_to_rotvec(quat: ArrayLike) -> Tensor:
    """Quaternion ``(..., 4)`` (normalised here) to axis-angle ``(..., 3)``, angle in [0, π].

    ``q`` and ``-q`` give the same result (canonicalised to ``w >= 0``).
    """
    quat, batch = _flatten(quat, "quat", (4,))
    return _quat_to_rotvec(quat).reshape(*batch, 3)


def quat_to_rotmat(quat: ArrayLike) -> Tensor:
    """Quaternion ``(..., 4)`` (normalised here) to rotation matrix ``(..., 3, 3)``."""
    quat, batch = _flatten(quat, "quat", (4,))
    return _quat_to_rotmat(quat).reshape(*batch, 3, 3)


def rotmat_to_quat(rotmat: ArrayLike) -> Tensor:
    """Rotation matrix ``(..., 3, 3)`` to unit quaternion ``(..., 4)`` with ``w >= 0``.

    Shepperd's method: of the four closed forms, the one dividing by the largest
    component is used, so the result is accurate at every angle including π.
    """
    rotmat, batch = _flatten(rotmat, "rotmat", (3, 3))
    return _rotmat_to_quat(rotmat).reshape(*batch, 4)


def rotvec_to_rotmat(rotvec: ArrayLike) -> Tensor:
    """Axis-angle ``(..., 3)`` to rotation matrix ``(..., 3, 3)`` by Rodrigues' formula.

    ``R = I + a K + b K²`` with ``K = [rotvec]×``, ``a = sin θ / θ = 2 cos(θ/2) sin(θ/2)/θ``
    and ``b = (1 - cos θ)/θ² = 2 (sin(θ/2)/θ)²``, written without cancellation.
    """
    rotvec, batch = _flatten(rotvec, "rotvec", (3,))
    cos_half, sinc_half = _half_angle_terms((rotvec * rotvec).sum(-1))
    a = (2 * cos_half * sinc_half)[:, None, None]
    b = (2 * sinc_half**2)[:, None, None]
    x, y, z = rotvec.unbind(-1)
    zero = torch.zeros_like(x)
    skew = torch.stack([zero, -z, y, z, zero, -x, -y, x, zero], -1).reshape(-1, 3, 3)
    eye = torch.eye(3, dtype=rotvec.dtype, device=rotvec.device)
    return (eye + a * skew + b * (skew @ skew)).reshape(*batch, 3, 3)


def rotmat_to_rotvec(rotmat: ArrayLike) -> Tensor:
    """Rotation matrix ``(..., 3, 3)`` to axis-angle ``(..., 3)``, angle in [0, π].

    Goes through :func:`rotmat_to_quat`, so it stays accurate near θ = π where
    ``acos((tr R - 1) / 2)`` loses half the digits.
    """
    rotmat, batch = _flatten(rotmat, "rotmat", (3, 3))
    return _quat_to_rotvec(_rotmat_to_quat(rotmat)).reshape(*batch, 3)


def quat_multiply(q1: ArrayLike, q2: ArrayLike) -> Tensor:
    """Hamilton product ``q1 q2`` of ``(..., 4)`` quaternions (broadcast); rotates by q2 first."""
    q1, q2, batch = _flatten_pair(q1, q2, ("q1", "q2"), (4,))
    w1, x1, y1, z1 = q1.unbind(-1)
    w2, x2, y2, z2 = q2.unbind(-1)
    product = [
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    ]
    return torch.stack(product, -1).reshape(*batch, 4)


def quat_conjugate(quat: ArrayLike) -> Tensor:
    """Conjugate ``(w, -x, -y, -z)`` of ``(..., 4)`` quaternions: the inverse of a unit one."""
    quat = _check(quat, "quat", (4,))
    return torch.cat([quat[..., :1], -quat[..., 1:]], dim=-1)


def quat_normalize(quat: ArrayLike) -> Tensor:
    """Scale ``(..., 4)`` quaternions to unit norm (input must be nonzero)."""
    quat, batch = _flatten(quat, "quat", (4,))
    return _normalize(quat).reshape(*batch, 4)


def quat_distance(q1: ArrayLike, q2: ArrayLike) -> Tensor:
    """``1 - |q1·q2|`` for unit ``(..., 4)`` quaternions (broadcast), shape ``(...)``.

    Equals ``1 - cos(θ/2)`` for the relative angle θ in [0, π]; lies in [0, 1]; zero for
    ``q2 = ±q1``. Gradients stay finite there (``|·|`` takes its sign as subgradient).
    """
    q1, q2, batch = _flatten_pair(q1, q2, ("q1", "q2"), (4,))
    return _quat_distance(q1, q2).reshape(batch)


def rotvec_distance(r1: ArrayLike, r2: ArrayLike) -> Tensor:
    """:func:`quat_distance` between axis-angle rotations ``(..., 3)`` (broadcast)."""
    r1, r2, batch = _flatten_pair(r1, r2, ("r1", "r2"), (3,))
    return _quat_distance(_rotvec_to_quat(r1), _rotvec_to_quat(r2)).reshape(batch)


def bend_twist(rotvecs: ArrayLike, bone: ArrayLike) -> tuple[float, float, np.ndarray]:
    """How a bone turns under a chain of rotations: ``rotvecs`` (K, 3) axis-angle composed
    in order (``q_0 q_1 ... q_K-1``), ``bone`` (3,) a unit vector. Returns (bend, twist,
    moved): the angle in radians between the bone and its image, the signed rotation about
    the bone in (-pi, pi], and the image (3,)."""
    q = rotvec_to_quat(as_tensor(rotvecs, torch.float64).reshape(-1, 3))
    qc = q[0]
    for k in range(1, len(q)):
        qc = quat_multiply(qc, q[k])
    bone = np.asarray(bone, np.float64)
    moved = quat_to_rotmat(qc).numpy() @ bone
    bend = float(np.arccos(np.clip(moved @ bone, -1.0, 1.0)))
    twist = 2 * np.arctan2(float(qc[1:].numpy() @ bone), float(qc[0]))
    return bend, float((twist + np.pi) % (2 * np.pi) - np.pi), moved
