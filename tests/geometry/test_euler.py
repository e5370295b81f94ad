"""Euler / Tait-Bryan angles: all 12 sequences, intrinsic and extrinsic, including gimbal lock."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from mocapkit.errors import ConfigError, ShapeError
from mocapkit.geometry import ALL_SEQUENCES, euler_from_quat, quat_from_euler, quat_to_xyzw
from tests.strategies import same_rotation, unit_quats

TOL = 1e-12  # a few ulps of double precision, see test_quaternion


def test_there_are_24_sequences() -> None:
    assert len(ALL_SEQUENCES) == 24
    assert len({s.lower() for s in ALL_SEQUENCES}) == 12


@pytest.mark.parametrize("seq", ALL_SEQUENCES)
@given(q=unit_quats())
def test_round_trip_every_sequence(seq: str, q: np.ndarray) -> None:
    angles = euler_from_quat(q, seq)
    assert same_rotation(quat_from_euler(angles, seq), q, 1e-11)


@pytest.mark.parametrize("seq", ALL_SEQUENCES)
def test_composition_matches_scipy(seq: str) -> None:
    angles = np.random.default_rng(2).uniform(-1.2, 1.2, size=(50, 3))
    q = quat_from_euler(angles, seq)
    expected = Rotation.from_euler(seq, angles).as_quat()
    assert same_rotation(quat_to_xyzw(q), expected, TOL)


@pytest.mark.parametrize("seq", ALL_SEQUENCES)
def test_decomposition_recovers_angles_in_range(seq: str) -> None:
    rng = np.random.default_rng(3)
    proper = seq[0].lower() == seq[2].lower()
    angles = rng.uniform(-3.0, 3.0, size=(200, 3))
    angles[:, 1] = rng.uniform(0.05, 3.09, 200) if proper else rng.uniform(-1.52, 1.52, 200)
    np.testing.assert_allclose(
        euler_from_quat(quat_from_euler(angles, seq), seq), angles, atol=1e-9
    )


@pytest.mark.parametrize("seq", ALL_SEQUENCES)
@given(a=st.floats(-3.0, 3.0), c=st.floats(-3.0, 3.0), at_upper=st.booleans())
def test_gimbal_lock_sets_third_angle_to_zero(seq: str, a: float, c: float, at_upper: bool) -> None:
    proper = seq[0].lower() == seq[2].lower()
    if proper:
        middle = np.pi if at_upper else 0.0
    else:
        middle = np.pi / 2 if at_upper else -np.pi / 2
    q = quat_from_euler([a, middle, c], seq)
    angles, gimbal = euler_from_quat(q, seq, return_gimbal=True)
    assert gimbal
    assert angles[2] == 0.0
    assert same_rotation(quat_from_euler(angles, seq), q, 1e-11)


def test_bad_sequences_are_rejected() -> None:
    for bad in ("xy", "xXz", "xxz", "abc", "XYY"):
        with pytest.raises(ConfigError, match="seq"):
            euler_from_quat([1, 0, 0, 0], bad)
    with pytest.raises(ShapeError, match=r"angles: expected shape \(3,\)"):
        quat_from_euler([1.0, 2.0], "xyz")
