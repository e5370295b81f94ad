"""Magnetometer hard- and soft-iron calibration from a rotation sequence (ellipsoid fit).

Model: a distorted reading is ``m_raw = W s + b`` where ``s`` is the true field in the
sensor frame (constant norm F while the sensor rotates), ``b`` the hard-iron offset
and ``W`` the soft-iron (and scale-factor) matrix. The readings lie on the ellipsoid
``(m - b)^T A (m - b) = 1`` with ``A = (W W^T)^-1 / F^2``. We fit the general quadric

    ``a x^2 + b y^2 + c z^2 + 2 f yz + 2 g xz + 2 h xy + 2 p x + 2 q y + 2 r z + d = 0``

by algebraic least squares (the right singular vector of the (N, 10) design matrix
with the smallest singular value), take ``b = -M^-1 [p, q, r]`` and
``A = M / (b^T M b - d)`` (M the symmetric matrix of the quadratic part), and
calibrate with ``m_cal = F sqrtm(A) (m_raw - b)``. Only the symmetric part of ``W`` is
identifiable (a rotation of the sensor frame is indistinguishable), so for symmetric
positive definite ``W`` and noise-free samples the fit is exact.

``F`` is the field strength of the calibrated output: given, or by default the
geometric mean of the ellipsoid's semi-axes (the volume-preserving choice, so the
units stay those of the input).

If the rotation sequence covers too few directions the ellipsoid is not determined;
the fit then raises a :class:`~mocapkit.errors.DataError` suggesting more rotation or
the hard-iron-only ``model="sphere"`` (4 parameters: centre and radius).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from mocapkit._validate import FloatArray, as_float_array, check_shape
from mocapkit.errors import ConfigError, DataError

# Coverage: the smallest eigenvalue of mean(u u^T) over the calibrated unit directions u
# (1/3 for a sphere covered evenly, 0 for rotations about a single axis). Below this
# the ellipsoid along the missing direction is guessed, not measured: a band of +-15 deg
# about a great circle gives about 0.02.
_MIN_COVERAGE = 0.02


def _coverage_error(detail: str) -> DataError:
    return DataError(
        f"mag: the rotation sequence covers too few directions to fit an ellipsoid ({detail}); "
        "rotate the sensor through all orientations (a figure-eight in every plane), or use "
        "model='sphere' for the hard-iron offset only"
    )


_MIN_SAMPLES = {"ellipsoid": 10, "sphere": 4}


@dataclass(frozen=True)
class MagCalibration:
    """Hard-iron offset ``hard_iron`` (3,) (input units), correction matrix ``soft_iron``
    (3, 3) (symmetric positive definite) and the calibrated field strength."""

    hard_iron: FloatArray
    soft_iron: FloatArray
    field_strength: float
    residual_rms: float  # RMS of |m_cal| - field_strength over the fitted samples
    n_samples: int
    model: str

    def apply(self, mag: Any) -> FloatArray:
        """Calibrate (N, 3) or (3,) readings: ``soft_iron @ (m - hard_iron)``. NaN rows
        (gaps) stay NaN."""
        m = as_float_array(mag, "mag")
        if m.ndim == 0 or m.shape[-1] != 3:
            raise ConfigError(f"mag: expected shape (3,) or (N, 3), got {m.shape}")
        return np.asarray((m - self.hard_iron) @ self.soft_iron.T)

    def as_dict(self) -> dict[str, Any]:
        return {
            "model": self.model,
            "hard_iron": self.hard_iron.tolist(),
            "soft_iron": self.soft_iron.tolist(),
            "field_strength": self.field_strength,
            "residual_rms": self.residual_rms,
            "n_samples": self.n_samples,
        }


def _sqrtm_spd(A: FloatArray) -> FloatArray:
    vals, vecs = np.linalg.eigh(A)
    return np.asarray((vecs * np.sqrt(vals)) @ vecs.T)


def _fit_sphere(m: FloatArray) -> tuple[FloatArray, FloatArray]:
    # |m|^2 = 2 c.m + (R^2 - |c|^2): linear in (c, k)
    D = np.column_stack([2.0 * m, np.ones(m.shape[0])])
    sol, *_ = np.linalg.lstsq(D, np.sum(m * m, axis=1), rcond=None)
    centre = sol[:3]
    radius2 = sol[3] + centre @ centre
    if not radius2 > 0:
        raise DataError("mag: the sphere fit failed (no positive radius); check the samples")
    return centre, np.eye(3) / radius2


def _fit_ellipsoid(m: FloatArray) -> tuple[FloatArray, FloatArray]:
    x, y, z = m.T
    D = np.column_stack(
        [x * x, y * y, z * z, 2 * y * z, 2 * x * z, 2 * x * y, 2 * x, 2 * y, 2 * z, np.ones_like(x)]
    )
    scale = np.linalg.norm(D, axis=0)  # column scaling for conditioning
    _, sv, vt = np.linalg.svd(D / scale, full_matrices=False)
    if sv[-2] < 1e-9 * sv[0]:
        raise _coverage_error(f"two quadrics fit exactly (singular values {sv[-2]:.3g})")
    a, b, c, f, g, h, p, q, r, d = vt[-1] / scale
    M = np.array([[a, h, g], [h, b, f], [g, f, c]])
    try:
        centre = -np.linalg.solve(M, np.array([p, q, r]))
    except np.linalg.LinAlgError:
        raise DataError("mag: the fitted quadric has no centre (not an ellipsoid)") from None
    k = centre @ M @ centre - d
    A = M / k
    if not np.all(np.linalg.eigvalsh(A) > 0):
        raise DataError(
            "mag: the fitted quadric is not an ellipsoid (the samples do not lie on a closed "
            "surface); rotate the sensor through more orientations or use model='sphere'"
        )
    return centre, A


def fit_mag_calibration(
    mag: Any,
    *,
    model: Literal["ellipsoid", "sphere"] = "ellipsoid",
    field_strength: float | None = None,
) -> MagCalibration:
    """Fit hard- and soft-iron parameters to readings taken while rotating the sensor.

    Args:
        mag: (N, 3) magnetometer readings (any unit); all-NaN rows (gaps) are skipped.
        model: ``"ellipsoid"`` (hard + soft iron, 9 parameters + scale) or ``"sphere"``
            (hard iron only).
        field_strength: norm of the calibrated field; default keeps the input scale.
    """
    if model not in _MIN_SAMPLES:
        raise ConfigError(f"model: expected 'ellipsoid' or 'sphere', got {model!r}")
    m = as_float_array(mag, "mag")
    check_shape(m, "mag", None, 3)
    rows = np.isfinite(m).all(axis=1)
    m = m[rows]
    if m.shape[0] < _MIN_SAMPLES[model]:
        raise DataError(
            f"mag: {m.shape[0]} finite samples, need at least {_MIN_SAMPLES[model]} for the "
            f"{model} fit (and many more, spread over all orientations, in practice)"
        )
    centre, A = _fit_sphere(m) if model == "sphere" else _fit_ellipsoid(m)
    if field_strength is None:
        strength = float(np.linalg.det(A) ** (-1.0 / 6.0))
    elif np.isfinite(field_strength) and field_strength > 0:
        strength = float(field_strength)
    else:
        raise ConfigError(f"field_strength: expected a positive number, got {field_strength}")
    soft = strength * _sqrtm_spd(A)
    calibrated = (m - centre) @ soft.T
    norms = np.linalg.norm(calibrated, axis=1)
    if model == "ellipsoid":
        u = calibrated / norms[:, None]
        coverage = float(np.linalg.eigvalsh(u.T @ u / u.shape[0])[0])
        if coverage < _MIN_COVERAGE:
            raise _coverage_error(f"coverage {coverage:.3f}, need {_MIN_COVERAGE}")
    residual = float(np.sqrt(np.mean((norms - strength) ** 2)))
    return MagCalibration(centre, soft, strength, residual, int(m.shape[0]), model)
