"""Quaternion algebra: hypothesis properties (near identity and pi) and SciPy cross-checks."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from scipy.spatial.transform import Rotation

from mocapkit.errors import DataError, ShapeError
from mocapkit.geometry import (
    quat_angle,
    quat_angle_between,
    quat_canonical,
    quat_conj,
    quat_exp,
    quat_from_axis_angle,
    quat_from_matrix,
    quat_from_rotvec,
    quat_from_two_vectors,
    quat_from_xyzw,
    quat_identity,
    quat_inv,
    quat_log,
    quat_mul,
    quat_normalize,
    quat_rotate,
    quat_rotate_inv,
    quat_slerp,
    quat_to_axis_angle,
    quat_to_matrix,
    quat_to_rotvec,
    quat_to_xyzw,
)
from tests.strategies import same_rotation, unit_quats, unit_vectors

# Double-precision round trips lose a few ulps per operation; 1e-12 leaves margin for
# ~100 ulps while catching any formula error (which shows at 1e-3 or worse).
TOL = 1e-12


@given(unit_quats(), unit_quats(), unit_quats())
def test_product_is_associative(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> None:
    np.testing.assert_allclose(quat_mul(quat_mul(a, b), c), quat_mul(a, quat_mul(b, c)), atol=TOL)


@given(unit_quats())
def test_inverse_gives_identity(q: np.ndarray) -> None:
    assert same_rotation(quat_mul(q, quat_inv(q)), quat_identity(), TOL)
    np.testing.assert_allclose(quat_conj(q), quat_inv(q), atol=TOL)


@given(unit_quats(), unit_vectors())
def test_rotate_matches_matrix_and_scipy(q: np.ndarray, v: np.ndarray) -> None:
    expected = Rotation.from_quat(quat_to_xyzw(q)).apply(v)
    np.testing.assert_allclose(quat_rotate(q, v), expected, atol=1e-12)
    np.testing.assert_allclose(quat_to_matrix(q) @ v, expected, atol=1e-12)
    np.testing.assert_allclose(quat_rotate_inv(q, quat_rotate(q, v)), v, atol=1e-12)


@given(unit_quats())
def test_matrix_round_trip(q: np.ndarray) -> None:
    R = quat_to_matrix(q)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert same_rotation(quat_from_matrix(R), q, TOL)
    assert quat_from_matrix(R)[0] >= 0.0


@given(unit_quats())
def test_exp_log_round_trip(q: np.ndarray) -> None:
    assert same_rotation(quat_exp(quat_log(q)), q, TOL)
    assert same_rotation(quat_from_rotvec(quat_to_rotvec(q)), q, TOL)


@given(unit_quats())
def test_rotvec_matches_scipy(q: np.ndarray) -> None:
    rv = quat_to_rotvec(q)
    expected = Rotation.from_quat(quat_to_xyzw(quat_canonical(q))).as_rotvec()
    # near pi the axis sign is ambiguous: compare the rotations, and the angle exactly
    assert np.isclose(np.linalg.norm(rv), np.linalg.norm(expected), atol=1e-9)
    assert same_rotation(quat_from_rotvec(rv), q, TOL)


@given(unit_vectors(), unit_quats())
def test_axis_angle_round_trip(axis: np.ndarray, q: np.ndarray) -> None:
    ax, ang = quat_to_axis_angle(q)
    assert same_rotation(quat_from_axis_angle(ax, ang), q, TOL)
    np.testing.assert_allclose(ang, quat_angle(q), atol=1e-12)


def test_small_angles_keep_precision() -> None:
    # 1e-9 rad about z: sin/angle formulas must not lose the angle to cancellation
    q = quat_from_rotvec([0.0, 0.0, 1e-9])
    np.testing.assert_allclose(quat_to_rotvec(q), [0.0, 0.0, 1e-9], rtol=1e-12)
    np.testing.assert_allclose(quat_angle(q), 1e-9, rtol=1e-12)


@given(unit_quats(), unit_quats())
def test_angle_between_is_symmetric_and_sign_invariant(a: np.ndarray, b: np.ndarray) -> None:
    d = quat_angle_between(a, b)
    assert 0.0 <= d <= np.pi
    np.testing.assert_allclose(d, quat_angle_between(b, -a), atol=1e-12)


@given(unit_quats(), unit_quats())
def test_slerp_endpoints_and_constant_speed(a: np.ndarray, b: np.ndarray) -> None:
    assert same_rotation(quat_slerp(a, b, 0.0), a, TOL)
    assert same_rotation(quat_slerp(a, b, 1.0), b, 1e-11)
    total = quat_angle_between(a, b)
    mid = quat_slerp(a, b, 0.25)
    np.testing.assert_allclose(quat_angle_between(a, mid), 0.25 * total, atol=1e-9)


def test_slerp_vectorised_over_t() -> None:
    a = quat_identity()
    b = quat_from_axis_angle([0, 0, 1], 1.0)
    out = quat_slerp(a, b, np.linspace(0, 1, 5))
    assert out.shape == (5, 4)
    np.testing.assert_allclose(quat_angle(out), np.linspace(0, 1, 5), atol=1e-12)


@given(unit_vectors(), unit_vectors())
def test_from_two_vectors(a: np.ndarray, b: np.ndarray) -> None:
    q = quat_from_two_vectors(a, b)
    np.testing.assert_allclose(quat_rotate(q, a), b, atol=1e-9)


def test_from_two_vectors_antiparallel() -> None:
    for a in ([1.0, 0, 0], [0, 0, 1.0], [0.6, 0.8, 0]):
        q = quat_from_two_vectors(a, -np.asarray(a))
        np.testing.assert_allclose(quat_rotate(q, a), -np.asarray(a), atol=1e-12)


def test_xyzw_edges() -> None:
    q = np.array([0.1, 0.2, 0.3, 0.4])
    np.testing.assert_array_equal(quat_to_xyzw(q), [0.2, 0.3, 0.4, 0.1])
    np.testing.assert_array_equal(quat_from_xyzw(quat_to_xyzw(q)), q)


def test_vectorised_shapes_broadcast() -> None:
    qs = quat_normalize(np.random.default_rng(1).normal(size=(7, 4)))
    v = np.array([1.0, 2.0, 3.0])
    assert quat_rotate(qs, v).shape == (7, 3)
    assert quat_mul(qs, quat_identity()).shape == (7, 4)
    assert quat_to_matrix(qs).shape == (7, 3, 3)
    assert quat_from_matrix(quat_to_matrix(qs)).shape == (7, 4)


def test_inputs_are_not_mutated() -> None:
    q = np.array([1.0, 2.0, 3.0, 4.0])
    before = q.copy()
    quat_conj(q)
    quat_normalize(q)
    quat_canonical(-q)
    np.testing.assert_array_equal(q, before)


def test_shape_errors_name_the_argument() -> None:
    with pytest.raises(ShapeError, match=r"q1: expected shape \(4,\) or \(N, 4\), got \(3,\)"):
        quat_mul([1, 0, 0], [1, 0, 0, 0])
    with pytest.raises(ShapeError, match=r"R: expected shape \(3, 3\)"):
        quat_from_matrix(np.eye(4))


def test_degenerate_inputs_raise() -> None:
    with pytest.raises(DataError, match="zero or non-finite quaternion"):
        quat_normalize([0.0, 0.0, 0.0, 0.0])
    with pytest.raises(DataError, match="zero or non-finite quaternion at index"):
        quat_normalize([[1.0, 0, 0, 0], [np.nan, 0, 0, 0]])
    with pytest.raises(DataError, match="zero-length rotation axis"):
        quat_from_axis_angle([0, 0, 0], 1.0)
    with pytest.raises(DataError, match="cannot invert a zero quaternion"):
        quat_inv([0, 0, 0, 0])
