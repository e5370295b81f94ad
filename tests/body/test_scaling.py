"""Static scaling and marker registration, and limb lengths from a dynamic trial, on
synthetic subjects whose true segment lengths and marker offsets are known."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from mocapkit.body.scaling import estimate_scales_from_motion, scale_from_static, stillest_window
from mocapkit.errors import DataError
from mocapkit.markers.kinematics import MarkerKinematics
from tests.markers import synthetic

TRUE_SCALES = {"thigh_r": 1.08, "thigh_l": 1.08, "shank_r": 0.95, "shank_l": 0.95, "pelvis": 1.05}


def _static_trial(n: int = 40) -> tuple[list[str], np.ndarray, np.ndarray, object, object]:
    human, ms = synthetic.subject(1.8, TRUE_SCALES)
    names = list(ms.names)
    q = human.neutral()
    q[human.dof_index("shoulder_adduction_r") + 1] = -0.2
    X = synthetic.markers(human, names, np.tile(q, (n, 1)))
    X[:, 1] = X[:, 1] + 0.0  # exact, still
    return names, np.arange(n) / 60.0, X, human, ms


def test_static_scaling_recovers_lengths_and_registers_exactly() -> None:
    names, t, X, _truth, ms = _static_trial()
    subject = scale_from_static(names, t, X, ms, 1.8, 75.0)
    s = subject.human.segment_scales
    # the knee / ankle centres are measured exactly (mid-condyle and mid-malleolus markers
    # sit symmetrically about the joint centre in the preset): lengths to 1 %
    assert s["thigh_r"] == pytest.approx(1.08, rel=0.01)
    assert s["shank_r"] == pytest.approx(0.95, rel=0.01)
    P = MarkerKinematics(subject.human, names).positions(subject.static_q)
    np.testing.assert_allclose(P, X[0], atol=1e-9)  # registration: exact at the static pose


def test_static_checks(caplog: pytest.LogCaptureFixture) -> None:
    names, t, X, _, ms = _static_trial()
    moving = X + np.linspace(0, 0.5, len(t))[:, None, None]  # drifting 30 mm/s
    with caplog.at_level(logging.WARNING):
        scale_from_static(names, t, moving, ms, 1.8, 75.0)
    assert "still moves (mean marker speed" in caplog.text
    with pytest.raises(DataError, match="only 3 markers of set 'gait2392' are visible"):
        scale_from_static(names[:3], t, X[:, :3], ms, 1.8, 75.0)
    assert stillest_window(t, moving).stop - stillest_window(t, moving).start == 30


def test_limb_lengths_from_motion_reduce_the_residual() -> None:
    human, ms = synthetic.subject(1.8, TRUE_SCALES)
    names = [n for n in ms.names if "Knee" not in n and "Ankle" not in n]
    Q = synthetic.motion(human, n=60, amplitude=0.3)
    X = synthetic.markers(human, names, Q)
    subject = estimate_scales_from_motion(names, X, ms, 1.8, 75.0, iterations=4, n_frames=20)
    res = subject.report["residual_mm"]
    assert res[-1] < 0.5 * res[0]  # alternating IK / linear solve lowers the residual
    assert res[-1] < 5.0  # measured 1-2 mm: the generic offsets are several cm off
