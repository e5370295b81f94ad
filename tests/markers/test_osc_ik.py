"""Direct marker control and the IK baseline on synthetic motion with exact answers, the fast
kernels against the Pinocchio references, and online against offline."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ConfigError, DataError
from mocapkit.markers.grouping import make_levels
from mocapkit.markers.ik import IKParams, initial_root_pose, solve_ik
from mocapkit.markers.osc import DirectMarkerController, OSCParams, reconstruct_offline
from tests.markers import synthetic

RATE = 60.0


@pytest.fixture(scope="module")
def case() -> dict:
    human, ms = synthetic.subject(1.8)
    names = [n for n in ms.names if "Knee" not in n and "Ankle" not in n]  # as in a walk trial
    Q = synthetic.motion(human, n=30, rate=RATE, amplitude=0.25)
    X = synthetic.markers(human, names, Q)
    weights = np.array([ms.spec(n).weight for n in names])
    return {"human": human, "ms": ms, "names": names, "Q": Q, "X": X, "w": weights}


def _levels(case: dict, strategy: str) -> tuple:
    human, ms, names = case["human"], case["ms"], case["names"]
    seg = {n: human.markers[n][0] for n in names}
    return make_levels(
        strategy, names, ms, seg, dict(zip(names, case["w"], strict=True)), human.segment_depth()
    )


def test_ik_recovers_exact_motion(case: dict) -> None:
    human, names, X, Q = case["human"], case["names"], case["X"], case["Q"]
    q0 = initial_root_pose(human, names, X[0], Q[0])
    q0[7:] = Q[0, 7:] + 0.05  # start a little off
    sol = solve_ik(
        human, names, X, case["w"], q0, case["ms"].coordinate_tasks, q_posture=Q[0],
        params=IKParams(posture_weight=1e-9, tol=1e-9),
    )  # fmt: skip
    from mocapkit.markers.kinematics import MarkerKinematics

    P = np.array([MarkerKinematics(human, names).positions(q) for q in sol.q])
    # markers consistent with the model and a negligible prior: sub-0.1 mm residuals
    assert np.abs(P - X).max() < 1e-4
    legs = [human.dof_index(d) + 1 for d in ("hip_flexion_r", "knee_angle_r", "ankle_angle_l")]
    np.testing.assert_allclose(sol.q[:, legs], Q[:, legs], atol=np.radians(0.5))
    lo, hi = human.dof_limits()
    assert (sol.q[:, 7:] >= lo - 1e-12).all()
    assert (sol.q[:, 7:] <= hi + 1e-12).all()


def test_ik_fast_matches_reference(case: dict) -> None:
    human, names, X, Q = case["human"], case["names"], case["X"][:3], case["Q"]
    q0 = initial_root_pose(human, names, X[0], Q[0])
    runs = [
        solve_ik(
            human, names, X, case["w"], q0, case["ms"].coordinate_tasks, params=IKParams(backend=b)
        )
        for b in ("fast", "reference")
    ]
    # same algorithm, same steps: the numba and numpy/Pinocchio paths agree to rounding
    np.testing.assert_allclose(runs[0].q[:, 7:], runs[1].q[:, 7:], atol=1e-8)
    np.testing.assert_allclose(runs[0].q[:, :3], runs[1].q[:, :3], atol=1e-8)


@pytest.mark.parametrize(("strategy", "mean_mm"), [("single", 1.5), ("independent", 12.0)])
def test_osc_tracks_exact_motion(case: dict, strategy: str, mean_mm: float) -> None:
    """Markers that the model can reach exactly, all 42 DOFs moving at up to 2.5 rad/s.
    One level: about a millimetre (measured 0.9 mm; the damped least squares and κ = 0.3
    lag a fast synthetic motion a little).
    The paper's independence rule over all markers: measured 7.9 mm mean — lower levels
    lose DOFs to the rank cut of nearly singular higher ones (see docs/benchmarks.md)."""
    human, names, X, Q = case["human"], case["names"], case["X"], case["Q"]
    levels = _levels(case, strategy)
    wmap = dict(zip(names, case["w"], strict=True))
    Qr, _P, DQ, E = reconstruct_offline(
        human, names, X, RATE, levels, case["ms"].coordinate_tasks, Q[0], Q[0], OSCParams(), wmap
    )
    assert np.nanmean(E) < mean_mm * 1e-3
    if strategy == "single":
        assert np.nanmax(E) < 6e-3  # measured 3.2 mm
        knee = human.dof_index("knee_angle_r") + 1
        np.testing.assert_allclose(Qr[:, knee], Q[:, knee], atol=np.radians(1.0))
    assert np.isfinite(DQ).all()


def test_osc_online_equals_offline_and_reference(case: dict) -> None:
    human, names, X, Q = case["human"], case["names"], case["X"][:6], case["Q"]
    levels = _levels(case, "single")
    wmap = dict(zip(names, case["w"], strict=True))
    tasks = case["ms"].coordinate_tasks
    off = reconstruct_offline(human, names, X, RATE, levels, tasks, Q[0], Q[0], OSCParams(), wmap)
    ctrl = DirectMarkerController(human, names, levels, tasks, Q[0], RATE, Q[0], OSCParams(), wmap)
    online = np.array([ctrl.step(x).q for x in X])
    np.testing.assert_allclose(online, off[0], atol=1e-12)  # the same computation
    ref = reconstruct_offline(
        human, names, X[:3], RATE, levels, tasks, Q[0], Q[0], OSCParams(backend="reference"), wmap
    )
    # y-space kernels vs the paper's formulas on Pinocchio: rounding, amplified by the dynamics
    np.testing.assert_allclose(ref[0][:, 7:], off[0][:3, 7:], atol=1e-8)
    np.testing.assert_allclose(ref[2], off[2][:3], atol=1e-8)


def test_paper_grouping_tracks_its_four_markers(case: dict) -> None:
    human, names, X, Q = case["human"], case["names"], case["X"], case["Q"]
    levels = _levels(case, "paper-only")
    assert levels == (("R.Acromium", "L.Wrist.Lat"), ("L.Elbow", "R.Wrist.Lat"))
    _, _, _, E = reconstruct_offline(
        human,
        names,
        X,
        RATE,
        levels,
        case["ms"].coordinate_tasks,
        Q[0],
        Q[0],
        OSCParams(substeps=4),
    )
    idx = [names.index(m) for level in levels for m in level]
    # four independent markers of a fast synthetic motion (every DOF moving at up to 2.5
    # rad/s): measured 1.3 mm mean, 9.3 mm at most (the first frames, catching up)
    assert np.nanmean(E[:, idx]) < 2e-3
    assert np.nanmax(E[:, idx]) < 12e-3


def test_osc_input_errors(case: dict) -> None:
    human, names = case["human"], case["names"]
    with pytest.raises(ConfigError, match="kappa: expected 0 < kappa < 1"):
        OSCParams(kappa=1.5)
    with pytest.raises(ConfigError, match="rate_hz: expected a positive frame rate"):
        DirectMarkerController(human, names, [names], {}, human.neutral(), 0.0)
    ctrl = DirectMarkerController(human, names, [names], {}, human.neutral(), RATE)
    with pytest.raises(DataError, match=f"x: expected shape \\({len(names)}, 3\\)"):
        ctrl.step(np.zeros((3, 3)))
    with pytest.raises(ConfigError, match="grouping 'nope'"):
        make_levels("nope", names, case["ms"], {n: "pelvis" for n in names}, {}, {})


def test_blocks_give_the_same_numbers(case: dict, monkeypatch: pytest.MonkeyPatch) -> None:
    """The kernels run a long trial in blocks (progress between them): bit for bit the
    numbers of one call."""
    import mocapkit.markers.ik as ik_mod
    import mocapkit.markers.osc as osc_mod

    human, names, X, Q, w = case["human"], case["names"], case["X"], case["Q"], case["w"]
    tasks = case["ms"].coordinate_tasks
    wmap = dict(zip(names, w, strict=True))
    one_osc = reconstruct_offline(human, names, X, RATE, [names], tasks, Q[0], Q[0], None, wmap)
    one_ik = solve_ik(human, names, X, w, Q[0], tasks, Q[0])
    seen: list[tuple[int, int]] = []
    monkeypatch.setattr(osc_mod, "BLOCK_FRAMES", 7)
    monkeypatch.setattr(ik_mod, "BLOCK_FRAMES", 7)
    blocks_osc = reconstruct_offline(
        human, names, X, RATE, [names], tasks, Q[0], Q[0], None, wmap,
        progress=lambda done, total: seen.append((done, total)),
    )  # fmt: skip
    blocks_ik = solve_ik(human, names, X, w, Q[0], tasks, Q[0])
    for a, b in zip(one_osc, blocks_osc, strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(one_ik.q, blocks_ik.q)
    assert seen == [(7, 30), (14, 30), (21, 30), (28, 30), (30, 30)]


def test_osc_follows_through_joint_limits_like_ik() -> None:
    """An arm that straightens to the elbow's limit, stays, and bends again (exact markers):
    direct marker control leaves the limit with the markers, as IK does (it used to hold a
    DOF that met its limit while the others overshot)."""
    human, ms = synthetic.subject(1.8)
    names = list(ms.names)
    n = 120
    t = np.arange(n) / RATE
    Q = np.tile(human.neutral(), (n, 1))
    lo, _hi = human.dof_limits()
    k_elbow = human.dof_index("elbow_flex_r") + 1
    k_knee = human.dof_index("knee_angle_l") + 1
    # elbow: 80 deg -> its lower limit (held 0.5 s) -> 80 deg; knee: to 150 deg and back
    ramp = np.clip(np.abs(t - 1.0) / 0.5 - 0.5, 0.0, 1.0)  # 1 -> 0 (held) -> 1
    Q[:, k_elbow] = lo[k_elbow - 7] + (np.radians(80.0) - lo[k_elbow - 7]) * ramp
    Q[:, k_knee] = np.radians(150.0) * (1.0 - ramp)
    Q[:, human.dof_index("hip_flexion_l") + 1] = np.radians(60.0) * (1.0 - ramp)
    X = synthetic.markers(human, names, Q)
    w = np.array([ms.spec(m).weight for m in names])
    Q_osc, _, _, _ = reconstruct_offline(
        human, names, X, RATE, [names], ms.coordinate_tasks, Q[0], human.neutral(),
        OSCParams(), dict(zip(names, w, strict=True)),
    )  # fmt: skip
    for k in (k_elbow, k_knee):
        err = np.degrees(np.abs(Q_osc[:, k] - Q[:, k]))
        # exact markers at 60 Hz: the simulation lags a fast ramp by a few degrees at most
        assert err[5:].max() < 3.0, (human.model.names[k - 6], err.max())
