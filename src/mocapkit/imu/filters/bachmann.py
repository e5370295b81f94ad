"""``bachmann``: the complementary quaternion attitude filter with a Gauss-Newton
correction (Bachmann, McGhee, Yun, Zyda 2001), the comparison of the seed paper's eq. 15.

One step, with ``q`` the estimate ``q_world_sensor``:

1. gyroscope integration, as in the paper's eq. 2-4: ``dq = 1/2 q [0, gyr dt]``,
   ``q_pred = (q + dq) / |q + dq|``;
2. measurement ``y0 = [acc/|acc|; mag/|mag|]`` (6,), the sensed gravity and magnetic
   field directions in the sensor frame;
3. computed measurement ``y(q) = [q* g_ref q; q* m_ref q]`` at ``q = q_pred``, with
   ``g_ref = [0, 0, 1]`` and the *full* field direction
   ``m_ref = [0, cos(dip), -sin(dip)]`` (ENU, dip measured at initialisation):
   Bachmann's filter compares the actual field vector, dip included, not a
   horizontal one;
4. ``eps(q) = y0 - y(q)`` and ``X = d y / d q`` (6 x 4), the partial derivatives with
   respect to the four components of q (:func:`measurement_jacobian`, analytic,
   tested against finite differences);
5. Gauss-Newton step, eq. 15: ``dq_gn = (X^T X)^-1 X^T eps``;
6. blend: ``q_next = q + dq + alpha dt dq_gn``, normalised. ``alpha`` [1/s] is the
   gain (Bachmann's ``k``): the step removes about ``alpha dt`` of the error, so
   ``1/alpha`` is the correction time constant.

Choices (the seed gives only eq. 15 and one sentence):

- Without a usable magnetometer sample (6D, a gap, a rejected sample) ``X`` has only
  the three gravity rows and rank 3 (a rotation about the vertical changes nothing),
  so ``X^T X`` is singular. The step is then the minimum-norm least-squares solution
  ``X^T (X X^T)^-1 eps`` (the Moore-Penrose solution, equal to eq. 15 whenever ``X``
  has full column rank); it never turns the heading. Likewise with only the
  magnetometer rows when the accelerometer sample is rejected.
- The four-component step also changes the norm of q; the normalisation removes it.
- Discretisation and time alignment as for ``miller`` (its choices 7 and 9): Euler
  integration, and ``y(q)``, ``X`` evaluated at the gyroscope-propagated estimate
  (the orientation at the readings' time).
- The accelerometer and magnetometer rows weigh the same, as in the original: a
  magnetic disturbance also tilts the estimate. That is the filter's known weakness
  and is kept.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_mul
from mocapkit.imu.filters.bachmann_kernel import bachmann_run_kernel
from mocapkit.imu.filters.base import (
    Backend,
    FilterInputs,
    FilterState,
    GainParams,
    OrientationFilter,
    register_filter,
)

DEFAULT_ALPHA = 0.16  # [1/s], tuned like miller's (docs/imu.md)
G_REF = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class BachmannParams(GainParams):
    """``alpha``: gain [1/s] on the Gauss-Newton step (time constant ``1/alpha``);
    ``0 <= alpha dt < 1``."""

    alpha: float = DEFAULT_ALPHA


@dataclass
class BachmannState(FilterState):
    """Orientation and the magnetic dip of the reference field."""


def field_reference(dip: float) -> FloatArray:
    """World (ENU) direction of the magnetic field with dip ``dip`` [rad] below north."""
    return np.array([0.0, np.cos(dip), -np.sin(dip)])


def computed_measurement(q: FloatArray, v: FloatArray) -> FloatArray:
    """``q* v q`` (3,) written as the quadratic form in q that :func:`measurement_jacobian`
    differentiates: ``(w^2 - |u|^2) v + 2 (u.v) u - 2 w (u x v)``, q = [w, u]."""
    w, u = q[0], q[1:]
    return (w * w - u @ u) * v + 2.0 * (u @ v) * u - 2.0 * w * np.cross(u, v)


def measurement_jacobian(q: FloatArray, v: FloatArray) -> FloatArray:
    """``d (q* v q) / d q`` (3, 4), columns for ``w, x, y, z``."""
    w, u = q[0], q[1:]
    v_cross = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    jac = np.empty((3, 4))
    jac[:, 0] = 2.0 * w * v - 2.0 * np.cross(u, v)
    jac[:, 1:] = (
        -2.0 * np.outer(v, u) + 2.0 * np.outer(u, v) + 2.0 * (u @ v) * np.eye(3) + 2.0 * w * v_cross
    )
    return jac


def gauss_newton_step(X: FloatArray, eps: FloatArray) -> FloatArray:
    """Eq. 15, ``(X^T X)^-1 X^T eps``, or ``X^T (X X^T)^-1 eps`` when X has 3 rows."""
    if X.shape[0] >= 4:
        return np.asarray(np.linalg.solve(X.T @ X, X.T @ eps), dtype=np.float64)
    return np.asarray(X.T @ np.linalg.solve(X @ X.T, eps), dtype=np.float64)


def bachmann_step(
    q: FloatArray,
    gyr: FloatArray,
    acc: FloatArray,
    mag: FloatArray,
    dt: float,
    use_acc: bool,
    use_mag: bool,
    m_ref: FloatArray,
    alpha: float,
) -> FloatArray:
    """One step from ``q`` (4,); returns the normalised next estimate."""
    dq = 0.5 * quat_mul(q, np.concatenate([[0.0], gyr * dt]))
    q_pred = (q + dq) / np.linalg.norm(q + dq)  # the orientation at the readings' time
    rows: list[FloatArray] = []
    residuals: list[FloatArray] = []
    if use_acc:
        rows.append(measurement_jacobian(q_pred, G_REF))
        residuals.append(acc / np.linalg.norm(acc) - computed_measurement(q_pred, G_REF))
    if use_mag:
        rows.append(measurement_jacobian(q_pred, m_ref))
        residuals.append(mag / np.linalg.norm(mag) - computed_measurement(q_pred, m_ref))
    q_next = q + dq
    if rows:
        step = gauss_newton_step(np.vstack(rows), np.concatenate(residuals))
        q_next = q_next + alpha * dt * step
    return q_next / np.linalg.norm(q_next)


class BachmannFilter(OrientationFilter):
    """Bachmann's Gauss-Newton complementary filter; see the module docstring."""

    name = "bachmann"
    state_type = BachmannState
    params: BachmannParams

    def __init__(self, params: BachmannParams, backend: Backend = "fast") -> None:
        if not isinstance(params, BachmannParams):
            raise ConfigError(f"params: expected BachmannParams, got {type(params).__name__}")
        super().__init__(params, backend)

    def _field(self) -> tuple[FloatArray, bool]:
        """(m_ref, usable): the magnetometer rows need the dip measured at initialisation."""
        dip = self.state.dip
        if not np.isfinite(dip):
            return np.zeros(3), False
        return field_reference(dip), True

    def _run_reference(self, inputs: FilterInputs) -> FloatArray:
        m_ref, mag_ok = self._field()
        q = np.array(self.state.quat, dtype=np.float64)
        out = np.empty((inputs.gyr.shape[0], 4))
        for i in range(out.shape[0]):
            q = bachmann_step(
                q,
                inputs.gyr[i],
                inputs.acc[i],
                inputs.mag[i],
                float(inputs.dt[i]),
                bool(inputs.use_acc[i]),
                bool(inputs.use_mag[i]) and mag_ok,
                m_ref,
                self.params.alpha,
            )
            out[i] = q
        self.state.quat = q.copy()
        return out

    def _run_fast(self, inputs: FilterInputs) -> FloatArray:
        m_ref, mag_ok = self._field()
        q = np.array(self.state.quat, dtype=np.float64)
        out = bachmann_run_kernel(q, *inputs[:6], m_ref, mag_ok, self.params.alpha)
        self.state.quat = q
        return out


@register_filter("bachmann")
def make_bachmann(rate_hz: float, backend: Backend = "fast", **params: Any) -> BachmannFilter:
    """Registry factory: ``make_filter("bachmann", rate_hz, alpha=...)``."""
    return BachmannFilter(BachmannParams(rate_hz=rate_hz, **params), backend)
