"""Tests for texvocab.geometry.rotations: extreme angles, round trips, distance, validation."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from texvocab.geometry.rotations import (
    as_tensor,
    quat_conjugate,
    quat_distance,
    quat_multiply,
    quat_normalize,
    quat_to_rotmat,
    quat_to_rotvec,
    rotmat_to_quat,
    rotmat_to_rotvec,
    rotvec_distance,
    rotvec_to_quat,
    rotvec_to_rotmat,
)

PI = math.pi
EXTREME_ANGLES = [0.0, 1e-8, PI - 1e-7, PI, 2 * PI]
DTYPES = [torch.float32, torch.float64]
TOL = {torch.float32: 2e-6, torch.float64: 1e-12}
_rng = np.random.default_rng(0)
_random_axes = _rng.normal(size=(3, 3))
AXES = np.concatenate([np.eye(3), -np.eye(3)[:1], _random_axes])
AXES /= np.linalg.norm(AXES, axis=1, keepdims=True)
FAST = settings(max_examples=200, deadline=None)
QUICK = settings(max_examples=100, deadline=None)


def scipy_quat(rot: Rotation) -> np.ndarray:
    """scipy's (x, y, z, w) as (w, x, y, z)."""
    return np.roll(rot.as_quat(), 1, axis=-1)


def assert_same_quat(q: torch.Tensor, ref: np.ndarray, tol: float) -> None:
    """Equal up to the sign of each quaternion."""
    q = q.detach().double().numpy()
    sign = np.where((q * ref).sum(-1, keepdims=True) < 0, -1.0, 1.0)
    np.testing.assert_allclose(q * sign, ref, atol=tol, rtol=0)


def assert_same_rotvec(out: torch.Tensor, ref: Rotation, tol: float) -> None:
    """Same rotation, angle in [0, π], and the very same vector away from θ = π."""
    out = out.detach().double().numpy()
    assert np.all(np.linalg.norm(out, axis=-1) <= PI + tol)
    got = Rotation.from_rotvec(out).as_matrix()
    np.testing.assert_allclose(got, ref.as_matrix(), atol=4 * tol, rtol=0)
    away = np.abs(ref.magnitude() - PI) > 1e-3
    np.testing.assert_allclose(out[away], ref.as_rotvec()[away], atol=4 * tol, rtol=0)


def skew(v: torch.Tensor) -> torch.Tensor:
    x, y, z = v
    return torch.tensor([[0, -z, y], [z, 0, -x], [-y, x, 0]], dtype=v.dtype)


# ------------------------------------------------------------ extreme angles


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("angle", EXTREME_ANGLES)
def test_values_at_extreme_angles(angle: float, dtype: torch.dtype) -> None:
    rotvec = torch.tensor(AXES * angle, dtype=dtype)
    ref = Rotation.from_rotvec(rotvec.double().numpy())  # from the same rounded input
    tol = TOL[dtype]
    quat = rotvec_to_quat(rotvec)
    rotmat = rotvec_to_rotmat(rotvec)
    assert quat.dtype == rotmat.dtype == dtype
    assert_same_quat(quat, scipy_quat(ref), tol)
    np.testing.assert_allclose(rotmat.double().numpy(), ref.as_matrix(), atol=tol, rtol=0)
    np.testing.assert_allclose(quat_to_rotmat(quat).double(), ref.as_matrix(), atol=tol, rtol=0)
    assert_same_quat(rotmat_to_quat(rotmat), scipy_quat(ref), tol)
    assert_same_rotvec(quat_to_rotvec(quat), ref, tol)
    assert_same_rotvec(rotmat_to_rotvec(rotmat), ref, tol)
    zero = torch.zeros(len(AXES), dtype=dtype)
    torch.testing.assert_close(rotvec_distance(rotvec, rotvec), zero, atol=tol, rtol=0)


@pytest.mark.parametrize("gap", [1e-3, 1e-5, 1e-7, 1e-8])
def test_rotmat_to_rotvec_accurate_near_pi(gap: float) -> None:
    """No acos((tr R - 1)/2) digit loss: the vector comes back to float64 precision."""
    rotvec = torch.tensor(AXES * (PI - gap))
    matrices = torch.tensor(Rotation.from_rotvec(rotvec.numpy()).as_matrix())
    torch.testing.assert_close(rotmat_to_rotvec(matrices), rotvec, atol=1e-14, rtol=0)
    torch.testing.assert_close(rotmat_to_rotvec(rotvec_to_rotmat(rotvec)), rotvec, atol=1e-14, rtol=0)


def test_two_pi_is_identity() -> None:
    rotvec = torch.tensor(AXES * 2 * PI)
    eye = torch.eye(3, dtype=torch.float64).expand(len(AXES), 3, 3)
    torch.testing.assert_close(rotvec_to_rotmat(rotvec), eye, atol=1e-14, rtol=0)
    back = quat_to_rotvec(rotvec_to_quat(rotvec))
    torch.testing.assert_close(back, torch.zeros_like(rotvec), atol=1e-14, rtol=0)
    assert torch.all(rotvec_distance(rotvec, torch.zeros(3)) < 1e-15)


def _grads(fn, x: torch.Tensor) -> torch.Tensor:
    x = x.detach().clone().requires_grad_(True)
    out = fn(x)
    weights = torch.linspace(-1.0, 1.0, out.numel(), dtype=out.dtype).reshape(out.shape)
    (grad,) = torch.autograd.grad((out * weights).sum(), x)
    return grad


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("angle", EXTREME_ANGLES)
def test_gradients_finite_at_extreme_angles(angle: float, dtype: torch.dtype) -> None:
    rotvec = torch.tensor(AXES * angle, dtype=dtype)
    quat = rotvec_to_quat(rotvec)
    rotmat = rotvec_to_rotmat(rotvec)
    cases = [
        (rotvec_to_quat, rotvec),
        (rotvec_to_rotmat, rotvec),
        (lambda r: rotvec_distance(r, rotvec), rotvec),
        (quat_to_rotvec, quat),
        (quat_to_rotmat, quat),
        (lambda q: quat_distance(q, quat), quat),
        (lambda q: quat_distance(q, -quat), quat),
        (rotmat_to_quat, rotmat),
        (rotmat_to_rotvec, rotmat),
    ]
    for fn, x in cases:
        assert torch.isfinite(_grads(fn, x)).all()


@pytest.mark.parametrize("dtype", DTYPES)
def test_jacobians_at_identity(dtype: torch.dtype) -> None:
    zero3 = torch.zeros(3, dtype=dtype)
    jac = torch.autograd.functional.jacobian(rotvec_to_quat, zero3)
    expected = torch.cat([torch.zeros(1, 3), 0.5 * torch.eye(3)]).to(dtype)
    torch.testing.assert_close(jac, expected)
    jac = torch.autograd.functional.jacobian(rotvec_to_rotmat, zero3)  # (3, 3, 3)
    for k in range(3):
        torch.testing.assert_close(jac[..., k], skew(torch.eye(3, dtype=dtype)[k]))
    identity = torch.tensor([1.0, 0, 0, 0], dtype=dtype)
    jac = torch.autograd.functional.jacobian(quat_to_rotvec, identity)
    torch.testing.assert_close(jac, torch.cat([torch.zeros(3, 1), 2 * torch.eye(3)], 1).to(dtype))


@pytest.mark.parametrize("angle", [0.0, 1e-8, 1e-4, 1.0, PI - 1e-3, PI - 1e-7])
def test_roundtrip_jacobian_is_identity(angle: float) -> None:
    """d/dv of rotvec -> (quat | rotmat) -> rotvec is I, also right next to 0 and π."""
    for axis in AXES:
        rotvec = torch.tensor(axis * angle)
        for fn in (
            lambda v: quat_to_rotvec(rotvec_to_quat(v)),
            lambda v: rotmat_to_rotvec(rotvec_to_rotmat(v)),
        ):
            jac = torch.autograd.functional.jacobian(fn, rotvec)
            torch.testing.assert_close(jac, torch.eye(3, dtype=torch.float64), atol=1e-6, rtol=0)


def test_gradcheck_float64() -> None:
    gen = torch.Generator().manual_seed(1)
    axes = torch.nn.functional.normalize(torch.randn(6, 3, generator=gen, dtype=torch.float64))
    generic = axes * torch.tensor([1e-4, 0.3, 1.0, 2.0, 2.8, 3.0], dtype=torch.float64)[:, None]
    smooth_everywhere = torch.cat([generic, torch.tensor(AXES) * PI, torch.tensor(AXES) * 2 * PI])
    smooth_everywhere = torch.cat([smooth_everywhere, torch.zeros(1, 3), torch.full((1, 3), 1e-8)])
    quat = rotvec_to_quat(generic)
    rotmat = rotvec_to_rotmat(generic)
    other = rotvec_to_quat(generic.flip(0))
    cases = [
        (rotvec_to_quat, smooth_everywhere),
        (rotvec_to_rotmat, smooth_everywhere),
        (quat_to_rotvec, quat * 1.3),  # also checks the built-in normalisation
        (quat_to_rotmat, quat),
        (rotmat_to_quat, rotmat),
        (rotmat_to_rotvec, rotmat),
        (lambda q: quat_multiply(q, other), quat),
        (lambda q: quat_distance(q, other), quat),
        (lambda r: rotvec_distance(r, generic.flip(0)), generic),
        (quat_normalize, quat * 2),
    ]
    for fn, x in cases:
        assert torch.autograd.gradcheck(fn, (x.clone().requires_grad_(True),))


# ------------------------------------------------------------ round trips (hypothesis)

unit3 = (
    st.tuples(*[st.floats(-1, 1)] * 3)
    .map(np.array)
    .filter(lambda a: np.linalg.norm(a) > 1e-3)
    .map(lambda a: a / np.linalg.norm(a))
)
unit4 = (
    st.tuples(*[st.floats(-1, 1)] * 4)
    .map(np.array)
    .filter(lambda a: np.linalg.norm(a) > 1e-3)
    .map(lambda a: a / np.linalg.norm(a))
)
angles = st.one_of(st.floats(0, PI), st.sampled_from([0.0, 1e-8, PI - 1e-7, PI]))
dtypes = st.sampled_from(DTYPES)
LOOSE = {torch.float32: 1e-5, torch.float64: 1e-12}


@FAST
@given(axis=unit3, angle=angles, dtype=dtypes)
def test_rotvec_roundtrips(axis: np.ndarray, angle: float, dtype: torch.dtype) -> None:
    rotvec = torch.tensor(axis * angle, dtype=dtype)
    ref = Rotation.from_rotvec(rotvec.double().numpy()[None])
    rotmat = rotvec_to_rotmat(rotvec)
    assert_same_rotvec(quat_to_rotvec(rotvec_to_quat(rotvec))[None], ref, LOOSE[dtype])
    assert_same_rotvec(rotmat_to_rotvec(rotmat)[None], ref, LOOSE[dtype])
    eye = torch.eye(3, dtype=dtype)
    torch.testing.assert_close(rotmat @ rotmat.T, eye, atol=LOOSE[dtype], rtol=0)
    assert abs(torch.linalg.det(rotmat).item() - 1) < LOOSE[dtype]


@FAST
@given(quat=unit4, dtype=dtypes)
def test_quat_roundtrips(quat: np.ndarray, dtype: torch.dtype) -> None:
    q = torch.tensor(quat, dtype=dtype)
    rotmat = quat_to_rotmat(q)
    ref = Rotation.from_quat(np.roll(quat, -1))
    tol = LOOSE[dtype]
    np.testing.assert_allclose(rotmat.double(), ref.as_matrix(), atol=tol, rtol=0)
    back = rotmat_to_quat(rotmat)
    assert back[0] >= 0 and abs(back.norm().item() - 1) < tol
    assert_same_quat(back, quat, 4 * tol)
    assert_same_quat(rotvec_to_quat(quat_to_rotvec(q)), quat, 4 * tol)
    if q[0] != 0:  # q and -q give the very same rotvec (at w = 0 both are valid at θ = π)
        torch.testing.assert_close(quat_to_rotvec(-q), quat_to_rotvec(q), atol=0, rtol=0)
    torch.testing.assert_close(rotmat @ rotmat.T, torch.eye(3, dtype=dtype), atol=tol, rtol=0)
    assert abs(torch.linalg.det(rotmat).item() - 1) < tol


@QUICK
@given(q1=unit4, q2=unit4)
def test_quat_multiply_composes_rotations(q1: np.ndarray, q2: np.ndarray) -> None:
    a, b = torch.tensor(q1), torch.tensor(q2)
    product = quat_multiply(a, b)
    torch.testing.assert_close(quat_to_rotmat(product), quat_to_rotmat(a) @ quat_to_rotmat(b))
    identity = quat_multiply(a, quat_conjugate(a))
    torch.testing.assert_close(identity, torch.tensor([1.0, 0, 0, 0], dtype=torch.float64))


# ------------------------------------------------------------ distance


@QUICK
@given(q1=unit4, q2=unit4, near=st.floats(0, 1e-3), flip=st.booleans())
def test_quat_distance_properties(q1: np.ndarray, q2: np.ndarray, near: float, flip: bool) -> None:
    a = torch.tensor(q1)
    b = quat_normalize(a + near * torch.tensor(q2)) if near > 0 else a.clone()
    b = -b if flip else b  # near-antipodal pairs when flipped
    for x, y in ((a, b), (a, torch.tensor(q2))):
        d = quat_distance(x, y)
        assert 0 <= d.item() <= 1
        assert d.item() == quat_distance(y, x).item()
        assert d.item() == quat_distance(x, -y).item()
        rel = Rotation.from_quat(np.roll(x.numpy(), -1)).inv() * Rotation.from_quat(np.roll(y.numpy(), -1))
        assert d.item() == pytest.approx(1 - math.cos(rel.magnitude() / 2), abs=1e-12)
        assert torch.isfinite(_grads(lambda q, y=y: quat_distance(q, y), x)).all()
    assert quat_distance(a, a).item() < 1e-15
    assert quat_distance(a, -a).item() < 1e-15


@QUICK
@given(axis1=unit3, axis2=unit3, angle1=angles, angle2=angles)
def test_rotvec_distance_matches_relative_angle(axis1, axis2, angle1, angle2) -> None:
    r1, r2 = axis1 * angle1, axis2 * angle2
    rel = (Rotation.from_rotvec(r1).inv() * Rotation.from_rotvec(r2)).magnitude()
    d = rotvec_distance(torch.tensor(r1), torch.tensor(r2)).item()
    assert d == pytest.approx(1 - math.cos(rel / 2), abs=1e-12)


# ------------------------------------------------------------ shapes, dtypes, numpy


@pytest.mark.parametrize("batch", [(), (0,), (5,), (2, 3)])
@pytest.mark.parametrize("dtype", DTYPES)
def test_batch_shapes_and_dtype(batch: tuple[int, ...], dtype: torch.dtype) -> None:
    rotvec = torch.randn(*batch, 3, generator=torch.Generator().manual_seed(0)).to(dtype)
    quat = rotvec_to_quat(rotvec)
    rotmat = rotvec_to_rotmat(rotvec)
    outputs = [
        (quat, (*batch, 4)),
        (rotmat, (*batch, 3, 3)),
        (quat_to_rotvec(quat), (*batch, 3)),
        (quat_to_rotmat(quat), (*batch, 3, 3)),
        (rotmat_to_quat(rotmat), (*batch, 4)),
        (rotmat_to_rotvec(rotmat), (*batch, 3)),
        (quat_multiply(quat, quat), (*batch, 4)),
        (quat_conjugate(quat), (*batch, 4)),
        (quat_normalize(quat), (*batch, 4)),
        (quat_distance(quat, quat), batch),
        (rotvec_distance(rotvec, rotvec), batch),
    ]
    for out, shape in outputs:
        assert out.shape == shape and out.dtype == dtype


def test_broadcasting_and_numpy_input() -> None:
    q1 = rotvec_to_quat(np.zeros((2, 1, 3)))
    assert q1.dtype == torch.float64
    q2 = rotvec_to_quat(np.random.default_rng(1).normal(size=(3, 3)).astype(np.float32))
    assert q2.dtype == torch.float32
    assert quat_distance(q1, q2).shape == (2, 3)
    assert quat_multiply(q1, q2).shape == (2, 3, 4)
    assert as_tensor(np.array([1, 2, 3])).dtype == torch.get_default_dtype()
    torch.testing.assert_close(rotvec_to_rotmat([0.0, 0.0, 0.0]), torch.eye(3))


# ------------------------------------------------------------ bad input


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_input_raises(bad: float) -> None:
    rotvec = torch.tensor([[0.1, bad, 0.2]])
    with pytest.raises(ValueError, match="rotvec must be finite"):
        rotvec_to_quat(rotvec)
    with pytest.raises(ValueError, match="rotvec must be finite"):
        rotvec_to_rotmat(rotvec)
    with pytest.raises(ValueError, match="quat must be finite"):
        quat_to_rotvec(torch.tensor([1.0, 0.0, bad, 0.0]))
    with pytest.raises(ValueError, match="rotmat must be finite"):
        rotmat_to_rotvec(torch.full((3, 3), bad))
    with pytest.raises(ValueError, match="q2 must be finite"):
        quat_distance(torch.tensor([1.0, 0, 0, 0]), torch.tensor([bad, 0, 0, 0]))


def test_wrong_shape_raises() -> None:
    with pytest.raises(ValueError, match=r"rotvec: expected shape \(\.\.\., 3\), got \(2, 4\)"):
        rotvec_to_quat(torch.zeros(2, 4))
    with pytest.raises(ValueError, match=r"expected shape \(\.\.\., 3\)"):
        rotvec_to_rotmat(torch.zeros(()))
    with pytest.raises(ValueError, match=r"quat: expected shape \(\.\.\., 4\)"):
        quat_to_rotmat(torch.zeros(3))
    with pytest.raises(ValueError, match=r"rotmat: expected shape \(\.\.\., 3, 3\)"):
        rotmat_to_quat(torch.zeros(2, 3, 4))
    with pytest.raises(ValueError, match=r"rotmat: expected shape \(\.\.\., 3, 3\)"):
        rotmat_to_rotvec(torch.zeros(3))
    with pytest.raises(ValueError, match=r"q1: expected shape \(\.\.\., 4\)"):
        quat_multiply(torch.zeros(5), torch.zeros(4))
