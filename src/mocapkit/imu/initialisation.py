"""Reference vectors and initial orientation from stationary samples, in ANY orientation.

The paper (section 3) averages accelerometer and magnetometer samples taken at rest,
normalises them into ``g_ref`` and ``m_init``, and corrects ``m_init`` for the
magnetic dip: with ``phi`` the angle between ``g_ref`` and ``m_init``, ``m_init`` is
rotated counterclockwise about ``g_ref x m_init`` by ``90 deg - phi`` to give the
horizontal ``m_ref``. ``g_ref`` and ``m_ref`` define the Earth frame E.

The paper then required the sensor to be initialised connectors-up, because its
microcontroller had room for one of the three cases of its trigonometric start-up
(section 6). Here the initial orientation comes from the two reference vectors by
the TRIAD construction (up = ``g_ref``, east = ``m_ref x up``, north = ``up x east``),
which has no special cases: every orientation works, including upside down. The
world frame is ENU (x magnetic east, y magnetic north, z up), so in the world
``g_ref = [0, 0, 1]`` and the dip-corrected ``m_ref = [0, 1, 0]``.

In 6D (no magnetometer) the heading is unobservable: :func:`initial_orientation`
applies the smallest rotation that makes a given prior estimate's vertical agree
with the accelerometer. Its axis is horizontal, so the prior's heading is kept
(identity prior: a fixed, deterministic heading). That is also what a re-initialisation
on command does in 6D: the inclination is reset, the heading stays continuous.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray, as_vectors, check_finite
from mocapkit.errors import DataError
from mocapkit.geometry import (
    quat_exp,
    quat_from_axis_angle,
    quat_from_matrix,
    quat_from_two_vectors,
    quat_identity,
    quat_mul,
    quat_normalize,
    quat_rotate,
)

UP_WORLD = np.array([0.0, 0.0, 1.0])
NORTH_WORLD = np.array([0.0, 1.0, 0.0])

# A mean vector shorter than this (in its own unit) has no direction: a dead sensor,
# free fall, or readings that cancel out over the window.
_MIN_NORM = 1e-6
# |sin| of the angle between gravity and the magnetic field below which the field is
# (anti)parallel to gravity and gives no heading (magnetic pole, or a disturbance).
_MIN_SIN_G_M = 1e-3


@dataclass(frozen=True)
class ReferenceVectors:
    """The paper's reference vectors, in the sensor frame at initialisation.

    Attributes:
        g_ref: (3,) unit vector, the mean accelerometer direction (up, since the
            accelerometer measures specific force).
        m_init: (3,) unit vector, the mean magnetometer direction, or None in 6D.
        m_ref: (3,) unit vector, ``m_init`` corrected for the dip (horizontal), or None.
        dip: magnetic dip [rad], the angle of the field below the horizontal
            (positive in the northern hemisphere); NaN in 6D.
        n_samples: number of samples averaged.
    """

    g_ref: FloatArray
    m_init: FloatArray | None
    m_ref: FloatArray | None
    dip: float
    n_samples: int


def _mean_direction(window: Any, name: str) -> tuple[FloatArray, int]:
    arr = as_vectors(window, name, 3)
    if arr.shape[0] == 0:
        raise DataError(f"{name}: empty window; pass at least one sample of shape (3,)")
    rows = np.isfinite(arr).all(axis=1)
    if not rows.any():
        raise DataError(f"{name}: no finite sample in the window of {arr.shape[0]} samples")
    check_finite(arr[rows], name)
    mean = arr[rows].mean(axis=0)
    norm = float(np.linalg.norm(mean))
    if norm < _MIN_NORM:
        raise DataError(
            f"{name}: the mean of {int(rows.sum())} samples has norm {norm:.3g}, no direction "
            "(all-zero readings, free fall, or a window that spans opposite orientations); "
            "initialise from samples taken at rest"
        )
    return mean / norm, int(rows.sum())


def dip_correct(g_ref: Any, m_init: Any) -> tuple[FloatArray, float]:
    """The paper's dip correction: rotate ``m_init`` about ``g_ref x m_init`` by 90 deg - phi.

    Args:
        g_ref, m_init: (3,) directions in the same frame (normalised here).

    Returns:
        ``(m_ref, dip)``: the horizontal unit field direction and the dip [rad]
        (``phi - 90 deg``; positive when the field points below the horizontal).
    """
    g = as_vectors(g_ref, "g_ref", 3)[0]
    m = as_vectors(m_init, "m_init", 3)[0]
    g = g / np.linalg.norm(g)
    m = m / np.linalg.norm(m)
    axis = np.cross(g, m)
    sin_phi = float(np.linalg.norm(axis))
    if sin_phi < _MIN_SIN_G_M:
        raise DataError(
            "mag: the magnetic field is parallel to gravity (angle "
            f"{np.degrees(np.arctan2(sin_phi, float(g @ m))):.2f} deg), so it gives no heading; "
            "move away from the magnetic disturbance or run in 6D (no magnetometer)"
        )
    phi = float(np.arctan2(sin_phi, float(g @ m)))
    correction = 0.5 * np.pi - phi
    q = quat_from_axis_angle(axis, correction)
    m_ref = quat_rotate(q, m)
    return m_ref / np.linalg.norm(m_ref), phi - 0.5 * np.pi


def reference_vectors(acc_window: Any, mag_window: Any = None) -> ReferenceVectors:
    """``g_ref``, ``m_init``, ``m_ref`` and the dip from samples taken at rest.

    Args:
        acc_window: (K, 3) or (3,) accelerometer samples [m/s^2] (any orientation).
        mag_window: (K', 3) or (3,) magnetometer samples (any unit), or None (6D).
            All-NaN rows (magnetometer gaps) are skipped.
    """
    g_ref, n = _mean_direction(acc_window, "acc")
    if mag_window is None:
        return ReferenceVectors(g_ref, None, None, float("nan"), n)
    m_init, _ = _mean_direction(mag_window, "mag")
    m_ref, dip = dip_correct(g_ref, m_init)
    return ReferenceVectors(g_ref, m_init, m_ref, dip, n)


def orientation_from_references(refs: ReferenceVectors, prior: Any = None) -> FloatArray:
    """``q_world_sensor`` (4,) with ``g_ref`` up and (9D) ``m_ref`` north, any orientation.

    In 6D (``refs.m_ref`` is None) the result is the smallest rotation of ``prior``
    (identity when None) that puts ``g_ref`` up, keeping the prior's heading.
    """
    up = refs.g_ref
    if refs.m_ref is not None:
        east = np.cross(refs.m_ref, up)
        east /= np.linalg.norm(east)
        north = np.cross(up, east)
        R_world_sensor = np.stack([east, north, up])  # rows: world axes in sensor coordinates
        return quat_from_matrix(R_world_sensor)
    q_prior = quat_identity() if prior is None else quat_normalize(np.asarray(prior, float))
    up_estimated = quat_rotate(q_prior, up)
    q_fix = quat_from_two_vectors(up_estimated, UP_WORLD)
    return quat_normalize(quat_mul(q_fix, q_prior))


def rotate_to_first_frame(gyr: Any, dt: Any, vectors: Any) -> FloatArray:
    """Express sensor-frame ``vectors`` (K, 3), sampled at K consecutive samples, in the
    sensor frame of the time just before the first sample, using the gyroscope.

    With ``D_i = exp(gyr_0 dt_0 / 2) * ... * exp(gyr_i dt_i / 2)`` (the rotation from that
    time to sample i, a gyroscope sample being the rate over the interval ending at it),
    the result is ``D_i v_i``. Averaging these instead of the raw samples removes the
    motion during an initialisation window, so a filter that starts moving starts right.
    """
    g = as_vectors(gyr, "gyr", 3)
    v = as_vectors(vectors, "vectors", 3)
    steps = np.broadcast_to(np.asarray(dt, dtype=np.float64), (g.shape[0],))
    # the half-angle exponentials and the rotations are vectorised; only the running
    # product is sequential, on Python floats (the arithmetic of quat_mul, term by term)
    e = quat_exp(0.5 * g * steps[:, None]).tolist()
    d = np.empty((v.shape[0], 4))
    w, x, y, z = 1.0, 0.0, 0.0, 0.0
    for i, (w2, x2, y2, z2) in enumerate(e):
        w, x, y, z = (
            w * w2 - x * x2 - y * y2 - z * z2,
            w * x2 + x * w2 + y * z2 - z * y2,
            w * y2 - x * z2 + y * w2 + z * x2,
            w * z2 + x * y2 - y * x2 + z * w2,
        )
        d[i] = w, x, y, z
    return quat_rotate(d, v)


def initial_orientation(acc_window: Any, mag_window: Any = None, prior: Any = None) -> FloatArray:
    """``q_world_sensor`` (4,) from stationary samples: see :func:`reference_vectors` and
    :func:`orientation_from_references`."""
    return orientation_from_references(reference_vectors(acc_window, mag_window), prior)
