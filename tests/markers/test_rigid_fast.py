"""Numba rigid-body kernels against Pinocchio, marker Jacobians against finite differences."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from mocapkit.markers import rigid_fast as rf
from mocapkit.markers.kinematics import MarkerKinematics
from tests.markers import synthetic


@pytest.fixture(scope="module")
def setup() -> tuple:
    human, ms = synthetic.subject(1.7, {"thigh_r": 1.1, "thorax": 0.9})
    kin = MarkerKinematics(human, list(ms.names))
    return human, kin, rf.flatten(human.model, kin.frame_ids)


def _random_state(human, seed: int) -> tuple[np.ndarray, np.ndarray]:  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(seed)
    q = human.neutral()
    q[:3] = rng.normal(size=3)
    quat = rng.normal(size=4)
    q[3:7] = quat / np.linalg.norm(quat)
    lo, hi = human.dof_limits()
    q[7:] = rng.uniform(lo, hi)
    return q, rng.normal(size=human.nv)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kernels_match_pinocchio(setup: tuple, seed: int) -> None:
    human, kin, fm = setup
    q, v = _random_state(human, seed)
    data = human.model.createData()
    R, t, S, V, Ab, A, h = rf.dynamics_terms(
        fm.parent, fm.R0, fm.p0, fm.axis, fm.mass, fm.com, fm.inertia, fm.gravity, q, v
    )
    P, J = rf.marker_kinematics(fm.parent, R, t, S, fm.marker_joint, fm.marker_offset)
    B = rf.marker_bias(R, t, V, Ab, fm.marker_joint, fm.marker_offset)
    P_ref, J_ref = kin.reference_positions_jacobians(q)
    # all double precision sums of O(10) terms of size O(1): 1e-9 leaves a wide margin
    np.testing.assert_allclose(P, P_ref, atol=1e-9)
    np.testing.assert_allclose(J, J_ref, atol=1e-9)
    np.testing.assert_allclose(B, kin.reference_bias(q, v), atol=1e-9)
    np.testing.assert_allclose(S.T, pin.computeJointJacobians(human.model, data, q), atol=1e-9)
    np.testing.assert_allclose(A, pin.crba(human.model, data, q), atol=1e-9)
    np.testing.assert_allclose(h, pin.nonLinearEffects(human.model, data, q, v), atol=1e-8)
    dv = 0.3 * v
    np.testing.assert_allclose(
        rf.integrate(q, dv)[:3], pin.integrate(human.model, q, dv)[:3], atol=1e-12
    )
    qa, qb = rf.integrate(q, dv)[3:7], np.asarray(pin.integrate(human.model, q, dv))[3:7]
    assert min(np.abs(qa - qb).max(), np.abs(qa + qb).max()) < 1e-12  # same rotation up to sign
    fast = MarkerKinematics(human, list(kin.names)).positions_jacobians_bias(q, v)
    np.testing.assert_allclose(fast[1], J_ref, atol=1e-9)
    np.testing.assert_allclose(fast[2], B, atol=1e-9)


def test_marker_jacobian_against_finite_differences(setup: tuple) -> None:
    human, kin, _ = setup
    q, _ = _random_state(human, 5)
    _, J = kin.positions_jacobians(q)
    eps = 1e-6
    for k in range(human.nv):
        dv = np.zeros(human.nv)
        dv[k] = eps
        fd = (
            kin.positions(pin.integrate(human.model, q, dv))
            - kin.positions(pin.integrate(human.model, q, -dv))
        ) / (2 * eps)
        # central differences: truncation O(eps²) and rounding O(1e-16 / eps) ~ 1e-10
        np.testing.assert_allclose(J[:, :, k], fd, atol=1e-7)
