"""Reference vectors, the paper's dip correction and initialisation in any orientation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given

from mocapkit.errors import DataError
from mocapkit.geometry import (
    quat_exp,
    quat_from_axis_angle,
    quat_identity,
    quat_mul,
    quat_rotate,
    quat_rotate_inv,
)
from mocapkit.imu.initialisation import (
    dip_correct,
    initial_orientation,
    orientation_from_references,
    reference_vectors,
    rotate_to_first_frame,
)
from tests.imu.synthetic import DIP, FIELD_WORLD, GRAVITY
from tests.strategies import same_rotation, unit_quats

# Exact synthetic vectors: only rounding separates the result from the truth.
TIGHT = 1e-12


def _readings(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return quat_rotate_inv(q, [0.0, 0.0, GRAVITY]), quat_rotate_inv(q, FIELD_WORLD)


def test_dip_correction_rotates_the_field_to_the_horizontal() -> None:
    g = np.array([0.0, 0.0, 1.0])
    m_ref, dip = dip_correct(g, FIELD_WORLD)
    np.testing.assert_allclose(m_ref, [0.0, 1.0, 0.0], atol=TIGHT)
    assert dip == pytest.approx(DIP, abs=TIGHT)
    # southern hemisphere: the field points up, the dip is negative
    m_ref, dip = dip_correct(g, [0.0, 30.0, 10.0])
    np.testing.assert_allclose(m_ref, [0.0, 1.0, 0.0], atol=TIGHT)
    assert dip == pytest.approx(-np.arctan2(10.0, 30.0), abs=TIGHT)


@given(unit_quats())
def test_initialisation_in_any_orientation(q_true: np.ndarray) -> None:
    acc, mag = _readings(q_true)
    q = initial_orientation(acc, mag)
    # the TRIAD construction is exact up to rounding; 1e-9 leaves room near pi
    assert same_rotation(q, q_true, 1e-9)


def test_initialisation_averages_the_window_and_reports_the_dip() -> None:
    q_true = quat_from_axis_angle([1.0, 2.0, -0.5], 2.5)
    acc, mag = _readings(q_true)
    rng = np.random.default_rng(3)
    noise = rng.normal(scale=0.05, size=(400, 3))
    refs = reference_vectors(acc + noise, mag + noise - noise[::-1])
    assert refs.n_samples == 400
    assert refs.dip == pytest.approx(DIP, abs=np.radians(0.2))  # noise averaged over 400
    np.testing.assert_allclose(
        quat_rotate(orientation_from_references(refs), refs.g_ref), [0, 0, 1], atol=1e-12
    )


def test_6d_initialisation_keeps_the_prior_heading() -> None:
    q_true = quat_from_axis_angle([0.3, -1.0, 0.2], 1.1)
    acc, _ = _readings(q_true)
    # the prior differs from the truth by a tilt only: the tilt is removed exactly
    tilt = quat_from_axis_angle([1.0, 0.5, 0.0], 0.4)
    q = initial_orientation(acc, None, prior=quat_mul(tilt, q_true))
    assert same_rotation(q, q_true, TIGHT)
    # no prior: the vertical is right, the heading is some fixed value
    q0 = initial_orientation(acc)
    np.testing.assert_allclose(quat_rotate(q0, acc / GRAVITY), [0.0, 0.0, 1.0], atol=TIGHT)
    # upside down works too
    q_flip = initial_orientation([0.0, 0.0, -GRAVITY])
    np.testing.assert_allclose(quat_rotate(q_flip, [0.0, 0.0, -1.0]), [0.0, 0.0, 1.0], atol=TIGHT)


def test_initialisation_errors_name_the_field() -> None:
    with pytest.raises(DataError, match=r"acc: the mean of 2 samples has norm 0, no direction"):
        reference_vectors(np.zeros((2, 3)))
    with pytest.raises(DataError, match="acc: empty window"):
        reference_vectors(np.zeros((0, 3)))
    with pytest.raises(DataError, match="mag: the magnetic field is parallel to gravity"):
        reference_vectors([0.0, 0.0, 9.8], [0.0, 0.0, -40.0])
    with pytest.raises(DataError, match="mag: no finite sample"):
        reference_vectors([0.0, 0.0, 9.8], np.full((3, 3), np.nan))


def test_rotate_to_first_frame_equals_the_sample_by_sample_product() -> None:
    rng = np.random.default_rng(4)
    gyr = rng.normal(size=(60, 3)) * 3.0
    gyr[::7] = 0.0  # the small-angle branch of quat_exp
    vectors = rng.normal(size=(60, 3))
    steps = rng.uniform(0.005, 0.02, size=60)
    expected = np.empty_like(vectors)
    d = quat_identity()
    for i in range(60):
        d = quat_mul(d, quat_exp(0.5 * gyr[i] * steps[i]))
        expected[i] = quat_rotate(d, vectors[i])
    # the same arithmetic in the same order: equal to the last bit
    np.testing.assert_array_equal(rotate_to_first_frame(gyr, steps, vectors), expected)
