"""Joint angles no human reaches are reported (issue 13: a calibration that turned a
segment round, or 6D headings that drifted apart, used to be written with exit 0)."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.body.plausibility import ImplausibleAnglesWarning, check_angles, warn_implausible
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.series import JointAngleSeries

TREE = SensorTree.preset("full_body_15")


def _angles(**deg: np.ndarray) -> JointAngleSeries:
    names = list(deg)
    n = len(next(iter(deg.values())))
    return JointAngleSeries(
        np.arange(n) / 100.0, names, np.radians(np.column_stack(list(deg.values())))
    )


def test_a_walk_is_plausible() -> None:
    t = np.linspace(0, 4 * np.pi, 400)
    walk = _angles(
        knee_angle_r=30 + 30 * np.sin(t), hip_flexion_r=10 + 25 * np.sin(t), pelvis_tilt=5 + 0 * t
    )
    assert check_angles(TREE, walk) == []


def test_a_knee_bent_backwards_is_named_with_its_sensor() -> None:
    t = np.linspace(0, 4 * np.pi, 400)
    flipped = _angles(knee_angle_r=-70 + 20 * np.sin(t), hip_flexion_r=10 + 25 * np.sin(t))
    with pytest.warns(
        ImplausibleAnglesWarning,
        match=r"knee_angle_r \(segment tibia_r, sensor lower_leg_right\) is outside -20..160 deg",
    ):
        (finding,) = warn_implausible(TREE, flipped)
    assert finding.worst_deg == pytest.approx(-90, abs=0.5)


def test_a_segment_turned_round_is_caught() -> None:
    turned = _angles(pelvis_tilt=np.full(100, 178.0))  # the pelvis calibrated upside down
    (finding,) = check_angles(TREE, turned)
    assert finding.segment == "pelvis"
    assert finding.outside_fraction == 1.0


def test_a_few_outliers_are_tolerated() -> None:
    knee = np.full(1000, 40.0)
    knee[:30] = -60.0  # 3 % of the samples (a glitch)
    assert check_angles(TREE, _angles(knee_angle_r=knee)) == []
