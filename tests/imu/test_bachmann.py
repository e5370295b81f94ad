"""Bachmann's Gauss-Newton filter: Jacobian, eq. 15, the rank-deficient 6D step,
convergence from a wrong start."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given

from mocapkit.geometry import (
    quat_angle_between,
    quat_from_axis_angle,
    quat_mul,
    quat_rotate,
    quat_rotate_inv,
)
from mocapkit.imu.filters import make_filter
from mocapkit.imu.filters.bachmann import (
    computed_measurement,
    field_reference,
    gauss_newton_step,
    measurement_jacobian,
)
from tests.imu.synthetic import constant_rotation
from tests.strategies import unit_quats


@given(unit_quats())
def test_jacobian_against_finite_differences(q: np.ndarray) -> None:
    v = np.array([0.2, -0.7, 0.6])
    np.testing.assert_allclose(computed_measurement(q, v), quat_rotate_inv(q, v), atol=1e-12)
    jac = measurement_jacobian(q, v)
    h = 1e-6
    numeric = np.column_stack(
        [
            (computed_measurement(q + h * e, v) - computed_measurement(q - h * e, v)) / (2 * h)
            for e in np.eye(4)
        ]
    )
    # central differences of a quadratic form are exact up to rounding (1e-16 / 1e-6)
    np.testing.assert_allclose(jac, numeric, atol=1e-9)


def test_gauss_newton_step_is_eq_15_and_min_norm_in_6d() -> None:
    q = quat_from_axis_angle([0.3, 0.2, 1.0], 0.8)
    m_ref = field_reference(np.radians(65.0))
    up = np.array([0.0, 0.0, 1.0])
    X = np.vstack([measurement_jacobian(q, up), measurement_jacobian(q, m_ref)])
    eps = np.array([0.01, -0.02, 0.005, 0.0, 0.01, -0.01])
    step = gauss_newton_step(X, eps)
    np.testing.assert_allclose(step, np.linalg.inv(X.T @ X) @ X.T @ eps, atol=1e-12)
    # gravity rows only: the minimum-norm solution, orthogonal to the null space (the
    # rotation about the vertical, which gravity cannot see)
    Xg = X[:3]
    step6 = gauss_newton_step(Xg, eps[:3])
    np.testing.assert_allclose(step6, np.linalg.pinv(Xg) @ eps[:3], atol=1e-12)
    up_body = quat_rotate_inv(q, [0.0, 0.0, 1.0])
    null = 0.5 * quat_mul(q, np.concatenate([[0.0], up_body]))  # d q / d(heading)
    assert abs(step6 @ null) < 1e-12


def test_6d_never_turns_the_heading() -> None:
    q0 = quat_from_axis_angle([0.0, 0.0, 1.0], 0.7)
    _, gyr, acc, _ = constant_rotation(q0, [0.0, 0.0, 0.0], 500)
    f = make_filter("bachmann", 100.0, alpha=5.0)
    f.reset(quat_mul(quat_from_axis_angle([1.0, 0.0, 0.0], 0.5), q0))  # tilted only
    out = f.run(gyr, acc)
    # the correction levels the estimate without any turn about the vertical
    x_axis = quat_rotate(out[-1], [1.0, 0.0, 0.0])
    assert np.degrees(np.arctan2(x_axis[1], x_axis[0])) == pytest.approx(np.degrees(0.7), abs=1e-6)
    assert np.degrees(quat_angle_between(out[-1], q0)) < 1e-6


@pytest.mark.parametrize("backend", ["fast", "reference"])
def test_converges_from_a_wrong_start_in_9d(backend: str) -> None:
    q0 = quat_from_axis_angle([0.5, -0.3, 0.8], 1.3)
    q_true, gyr, acc, mag = constant_rotation(q0, [0.05, -0.1, 0.2], 1500, 100.0)
    f = make_filter("bachmann", 100.0, backend, alpha=2.0)
    f.reset(
        quat_mul(
            quat_from_axis_angle([0.0, 0.0, 1.0], np.radians(120.0)),
            quat_mul(quat_from_axis_angle([1.0, 0.0, 0.0], np.radians(100.0)), q0),
        ),
        dip=np.radians(65.0),
    )
    out = f.run(gyr, acc, mag)
    err = np.degrees(quat_angle_between(out, q_true))
    assert err[0] > 100.0
    assert err[-1] < 1e-4  # exact signals: only the first-order integration error remains
