"""The prioritized torque (eq. 6-13) against the paper's formulas, and the error bound."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.markers.osc_reference import prioritized_torque_reference
from mocapkit.markers.prioritized import joint_error_bound_reference, prioritized_torque


def _problem(seed: int, nv: int = 12) -> tuple:
    rng = np.random.default_rng(seed)
    M = rng.normal(size=(nv, nv))
    A = M @ M.T + nv * np.eye(nv)
    J = rng.normal(size=(12, nv))
    return (
        A,
        np.linalg.cholesky(A),
        rng.normal(size=nv),
        J,
        rng.normal(size=12),
        rng.normal(size=12) * 0.1,
    )


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("damping", [1e-6, 0.1])
def test_matches_reference(seed: int, damping: float) -> None:
    A, LA, h, J, acc, bias = _problem(seed)
    ptr = np.array([0, 3, 9, 12])
    ap = np.ones(A.shape[0])
    dx = np.linspace(-1, 1, 12)
    G, qdd, dq = prioritized_torque(A, LA, h, J, acc, bias, ptr, ap, dx, True, damping)
    G_ref, Jbar_ref = prioritized_torque_reference(A, h, J, acc, bias, list(ptr), ap, damping)
    # the y-space and joint-space forms are algebraically equal; rounding ~1e-12 relative
    np.testing.assert_allclose(G, G_ref, rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(qdd, np.linalg.solve(A, G - h), atol=1e-9)
    np.testing.assert_allclose(dq, Jbar_ref @ dx, atol=1e-8)


def test_lower_levels_do_not_disturb_higher_ones() -> None:
    A, LA, h, J, acc, bias = _problem(3)
    ptr = np.array([0, 3, 12])
    no = np.zeros(12)
    _, qdd_a, _ = prioritized_torque(A, LA, h, J, acc, bias, ptr, no, no, False, 1e-8)
    other = acc.copy()
    other[3:] += 50.0  # very different lower-level targets
    _, qdd_b, _ = prioritized_torque(A, LA, h, J, other, bias, ptr, np.ones(12), no, False, 1e-8)
    top_a = J[:3] @ qdd_a + bias[:3]
    top_b = J[:3] @ qdd_b + bias[:3]
    np.testing.assert_allclose(top_a, acc[:3], atol=1e-5)  # achieved up to the damping 1e-8
    np.testing.assert_allclose(top_b, top_a, atol=1e-9)  # projectors are exact: rounding only
    # a level that repeats rows of a higher one has nothing left and gets no force
    J3 = np.vstack([J[:3], J[:3]])
    ptr3 = np.array([0, 3, 6])
    acc3 = np.concatenate([acc[:3], acc[:3] + 100.0])
    _, qdd3, _ = prioritized_torque(
        A, LA, h, J3, acc3, np.zeros(6), ptr3, np.zeros(12), np.zeros(6), False, 1e-8
    )
    np.testing.assert_allclose(J[:3] @ qdd3, acc[:3], atol=1e-6)


def test_error_bound_eq15() -> None:
    A, LA, h, J, acc, bias = _problem(4)
    dx = np.random.default_rng(9).normal(size=12)
    _, _, dq = prioritized_torque(
        A, LA, h, J, acc, bias, np.array([0, 12]), np.zeros(12), dx, True, 1e-9
    )
    ref = joint_error_bound_reference(np.linalg.inv(A), J, dx)
    # the damping floor (1e-10 of ‖B‖²) moves a well-posed answer by ~1e-7 relative
    np.testing.assert_allclose(dq, ref, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(J @ dq, dx, atol=1e-4)  # square, full rank: Δx = J Δq (eq. 14)


@pytest.mark.parametrize(
    ("nv", "n_lock", "rows"), [(12, 3, 12), (48, 6, 123), (48, 0, 123), (20, 2, 9)]
)
@pytest.mark.parametrize("damping", [1e-6, 0.01])
def test_single_level_route_equals_the_general_one(
    nv: int, n_lock: int, rows: int, damping: float
) -> None:
    """[held DOFs] > [one marker level] > posture: the joint-space route of
    prioritized_torque_single gives the y-space route's Γ, q̈ and bound."""
    from mocapkit.markers.prioritized import prioritized_torque_single

    rng = np.random.default_rng(nv + n_lock + rows)
    M = rng.normal(size=(nv, nv))
    A = M @ M.T + nv * np.eye(nv)
    LA = np.linalg.cholesky(A)
    h, J = rng.normal(size=nv), rng.normal(size=(rows, nv))
    acc, bias = rng.normal(size=rows), 0.1 * rng.normal(size=rows)
    cols = np.sort(rng.choice(nv, n_lock, replace=False)).astype(np.int64)
    lock_acc, ap, dx = rng.normal(size=n_lock), rng.normal(size=nv), rng.normal(size=rows)
    J_all = np.vstack([np.eye(nv)[cols], J])
    ptr = np.array([0, n_lock, n_lock + rows])
    zeros = np.zeros(n_lock)
    G1, x1, d1 = prioritized_torque(
        A, LA, h, J_all, np.concatenate([lock_acc, acc]), np.concatenate([zeros, bias]), ptr,
        ap, np.concatenate([zeros, dx]), True, damping, True,
    )  # fmt: skip
    G2, x2, d2 = prioritized_torque_single(
        A, LA, h, cols, lock_acc, J, acc, bias, ap, dx, True, damping
    )
    # algebraically equal routes; rounding ~1e-13 relative (1e-10 with a nearly undamped,
    # nearly square level)
    for a, b in ((G1, G2), (x1, x2), (d1, d2)):
        np.testing.assert_allclose(b, a, rtol=1e-8, atol=1e-8 * np.abs(a).max())
