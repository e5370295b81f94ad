"""The numba kernels of the error bounds equal their readable numpy references."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.markers.bound_fit import fit_to_markers, total_bound
from mocapkit.markers.bounds import coordinate_jacobian, sensitivities
from mocapkit.markers.coordinates import coordinate_map, coordinates_from_q
from mocapkit.markers.determined import column_determined, dof_determined
from tests.markers import synthetic


@pytest.fixture(scope="module")
def case() -> dict:
    """Exact markers of a moving pose, 3 mm noise, some markers missing in some frames, the
    model pose off the truth by a few degrees: every branch of the kernels (gaps, rank
    deficiency, limits) is exercised."""
    rng = np.random.default_rng(7)
    human, ms = synthetic.subject(1.75)
    names = list(ms.names)
    n = 12
    Q_true = np.tile(human.neutral(), (n, 1))
    for dof, amp in (("knee_angle_r", 70.0), ("hip_flexion_l", 40.0), ("elbow_flex_r", 90.0)):
        Q_true[:, human.dof_index(dof) + 1] = np.radians(amp) * np.linspace(0.1, 1.0, n)
    # one DOF driven to its limit, so the fit meets the projection
    k = human.dof_index("knee_angle_l") + 1
    Q_true[:, k] = human.model.upperPositionLimit[k]
    X = synthetic.markers(human, names, Q_true) + rng.normal(0.0, 0.003, (n, len(names), 3))
    X[3:6, :5] = np.nan  # a gap on some markers
    X[8, 10:] = np.nan  # a frame that sees few markers
    Q = Q_true.copy()
    Q[:, 7:] += np.radians(rng.normal(0.0, 3.0, Q[:, 7:].shape))
    Q[:, 7:] = np.clip(
        Q[:, 7:], human.model.lowerPositionLimit[7:], human.model.upperPositionLimit[7:]
    )
    w = np.array([ms.spec(m).weight for m in names])
    root, dofs = dof_determined(human, names, names, X)
    free = np.concatenate([np.repeat(root[:, None], 6, axis=1), dofs], axis=1)
    cmap = coordinate_map(human)
    rows = column_determined(cmap, root, dofs) & cmap.angular[None, :]
    return {"human": human, "names": names, "Q": Q, "X": X, "w": w, "free": free,
            "cmap": cmap, "rows": rows}  # fmt: skip


def test_sensitivities_kernel_equals_reference(case: dict) -> None:
    c = case
    G = coordinate_jacobian(c["human"], c["cmap"], c["Q"])
    args = (c["human"], c["names"], c["Q"], c["X"], c["w"], c["free"], G, c["rows"])
    fast, ref = sensitivities(*args, backend="fast"), sensitivities(*args, backend="reference")
    assert np.isfinite(ref).sum() > 100  # not vacuous
    np.testing.assert_array_equal(np.isnan(fast), np.isnan(ref))
    np.testing.assert_array_equal(np.isinf(fast), np.isinf(ref))
    fin = np.isfinite(ref)
    # same arithmetic up to LAPACK's summation order: 1e-9 relative
    np.testing.assert_allclose(fast[fin], ref[fin], rtol=1e-9, atol=1e-12)


def test_fit_kernel_equals_reference_and_lowers_the_cost(case: dict) -> None:
    c = case
    args = (c["human"], c["names"], c["Q"], c["X"], c["w"], c["free"])
    fast, ref = fit_to_markers(*args, backend="fast"), fit_to_markers(*args, backend="reference")
    # the same projected Levenberg-Marquardt iterations; LAPACK (numba) and numpy's solve
    # round differently, which the stopping test can see at the last iteration
    np.testing.assert_allclose(fast, ref, atol=1e-7)
    from mocapkit.markers.kinematics import MarkerKinematics

    kin = MarkerKinematics(c["human"], c["names"])

    def cost(Q: np.ndarray) -> np.ndarray:
        P = np.array([kin.positions(q) for q in Q]).reshape(c["X"].shape)
        e = np.where(np.isfinite(c["X"]), P - c["X"], 0.0)
        return (c["w"][None, :, None] * e**2).sum(axis=(1, 2))

    assert (cost(fast) <= cost(c["Q"]) + 1e-12).all()  # a fit never makes it worse
    lo, hi = c["human"].model.lowerPositionLimit, c["human"].model.upperPositionLimit
    assert ((fast[:, 7:] >= lo[7:] - 1e-12) & (fast[:, 7:] <= hi[7:] + 1e-12)).all()


def test_total_bound_kernel_equals_reference(case: dict) -> None:
    c = case
    args = (c["human"], c["cmap"], c["names"], c["Q"], c["X"], c["w"], c["free"], c["rows"])
    fast, ref = total_bound(*args, backend="fast"), total_bound(*args, backend="reference")
    assert np.isfinite(ref).sum() > 100
    np.testing.assert_array_equal(np.isnan(fast), np.isnan(ref))
    fin = np.isfinite(ref)
    np.testing.assert_allclose(fast[fin], ref[fin], rtol=1e-6, atol=1e-7)


def test_coordinate_jacobian_matches_finite_differences_through_pinocchio(case: dict) -> None:
    """The vectorised perturbation of the free-flyer equals ``pin.integrate``'s."""
    import pinocchio as pin

    c = case
    human, cmap, Q = c["human"], c["cmap"], c["Q"][:3]
    G = coordinate_jacobian(human, cmap, Q)
    eps = 1e-6
    for k in range(human.nv):
        dv = np.zeros(human.nv)
        dv[k] = eps
        up = np.array([pin.integrate(human.model, q, dv) for q in Q])
        down = np.array([pin.integrate(human.model, q, -dv) for q in Q])
        d = coordinates_from_q(human, up, cmap) - coordinates_from_q(human, down, cmap)
        d[:, cmap.angular] = np.pi - np.mod(np.pi - d[:, cmap.angular], 2.0 * np.pi)
        np.testing.assert_allclose(G[:, :, k], d / (2 * eps), atol=1e-6)


def test_analytic_coordinate_jacobian_equals_finite_differences() -> None:
    """Random poses over the joint ranges and pelvis orientations (both Euler branches of
    the derived joints occur): the analytic Jacobian equals central differences."""
    from mocapkit.markers.bounds import coordinate_jacobian_reference

    rng = np.random.default_rng(3)
    human, _ = synthetic.subject(1.75)
    cmap = coordinate_map(human)
    n = 40
    Q = np.tile(human.neutral(), (n, 1))
    lo, hi = human.model.lowerPositionLimit[7:], human.model.upperPositionLimit[7:]
    Q[:, 7:] = lo + (hi - lo) * rng.uniform(0.05, 0.95, (n, lo.size))
    quat = rng.normal(size=(n, 4))
    Q[:, 3:7] = quat / np.linalg.norm(quat, axis=1)[:, None]
    Q[:, :3] = rng.normal(size=(n, 3))
    G = coordinate_jacobian(human, cmap, Q)
    ref = coordinate_jacobian_reference(human, cmap, Q)
    # central differences with step 1e-6: truncation and rounding ~1e-8
    np.testing.assert_allclose(G, ref, atol=1e-6)
