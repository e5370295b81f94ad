"""The programmatic skeleton: structure, inertia (CRBA against kinetic energy), anthropometry."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from mocapkit.body.anthropometry import segment_parameters, total_mass_fraction
from mocapkit.body.human_model import anatomical_joint_names, build_human_model
from mocapkit.errors import ConfigError


def test_structure() -> None:
    h = build_human_model(1.75, 70.0)
    assert len(anatomical_joint_names(h)) == 25
    assert h.nv == 48
    assert h.nq == 49
    assert pin.computeTotalMass(h.model) == pytest.approx(70.0)
    for name in (
        "hip_flexion_r",
        "knee_angle_l",
        "ankle_angle_r",
        "abdomen_extension",
        "elbow_flex_r",
        "pro_sup_l",
        "wrist_dev_r",
    ):
        assert name in h.dof_names
    lo, hi = h.dof_limits()
    assert (lo < 0).all() or (lo <= 0).all()
    assert (hi > lo).all()


def test_mass_matrix_matches_kinetic_energy() -> None:
    """Pinocchio's CRBA assumes a depth-first joint order; a wrong order gives a wrong A.
    A is checked against the polarised kinetic energy."""
    h = build_human_model(1.8, 80.0)
    model, data = h.model, h.model.createData()
    q = h.neutral()
    q[7:] = np.random.default_rng(0).uniform(-0.3, 0.3, h.nv - 6)
    A = pin.crba(model, data, q).copy()
    eye = np.eye(h.nv)
    ke = lambda v: pin.computeKineticEnergy(model, data, q, v)  # noqa: E731
    K = np.array(
        [[ke(eye[i] + eye[j]) - ke(eye[i]) - ke(eye[j]) for j in range(h.nv)] for i in range(h.nv)]
    )
    np.testing.assert_allclose(A, K, atol=1e-10)  # rounding of sums of ~1e2 terms
    assert np.linalg.eigvalsh(A).min() > 0


def test_conventions_of_signs() -> None:
    """Hip flexion moves the knee forward, knee_angle > 0 moves the ankle back (Rajagopal;
    gait2392's knee is negative in flexion), elbow_flex > 0 brings the hand forward."""
    h = build_human_model(1.8, 75.0)
    data = h.model.createData()

    def pos(q: np.ndarray, seg: str) -> np.ndarray:
        pin.framesForwardKinematics(h.model, data, q)
        return np.array(data.oMf[h.model.getFrameId(seg)].translation)

    q0 = h.neutral()
    q = q0.copy()
    q[h.dof_index("hip_flexion_r") + 1] = 0.3
    assert pos(q, "shank_r")[0] > pos(q0, "shank_r")[0] + 0.1
    q = q0.copy()
    q[h.dof_index("knee_angle_r") + 1] = 0.5
    assert pos(q, "talus_r")[0] < pos(q0, "talus_r")[0] - 0.1
    q = q0.copy()
    q[h.dof_index("elbow_flex_l") + 1] = 1.0
    assert pos(q, "hand_l")[0] > pos(q0, "hand_l")[0] + 0.15
    q = q0.copy()
    q[h.dof_index("hip_adduction_r") + 1] = 0.3
    assert pos(q, "shank_r")[1] > pos(q0, "shank_r")[1] + 0.05  # right leg moves left


def test_anthropometry_scales_and_checks() -> None:
    assert total_mass_fraction("male") == pytest.approx(1.0, abs=2e-3)  # table rounding
    assert total_mass_fraction("female") == pytest.approx(1.0, abs=2e-3)
    a, b = segment_parameters(1.6, 60), segment_parameters(1.8, 60)
    assert b["thigh"].length / a["thigh"].length == pytest.approx(1.8 / 1.6)
    with pytest.raises(ConfigError, match="looks like centimetres"):
        segment_parameters(175, 70)
    with pytest.raises(ConfigError, match="sex: expected 'male' or 'female'"):
        segment_parameters(1.7, 70, "x")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="segment_scales\\['thigh_r'\\] = 5.0"):
        build_human_model(segment_scales={"thigh_r": 5.0})
    with pytest.raises(ConfigError, match="unknown segment 'femur'"):
        build_human_model(segment_scales={"femur": 1.0})


def test_with_markers_replaces_previous_markers() -> None:
    h = build_human_model()
    a = h.with_markers({"M": ("thigh_r", [0.1, 0, 0])})
    b = a.with_markers({"M": ("thigh_r", [0.2, 0, 0])})
    frames = [f for f in b.model.frames if f.name == "marker:M"]
    assert len(frames) == 1
    np.testing.assert_allclose(frames[0].placement.translation, [0.2, 0, 0])
    with pytest.raises(ConfigError, match="segment 'femur' is not in the model"):
        h.with_markers({"M": ("femur", [0, 0, 0])})
