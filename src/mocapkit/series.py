"""Typed, validated time series shared by every stage: IMU recordings and orientation series.

Rules (STYLE.md): time is the first axis and is in seconds; SI units inside
(gyroscope rad/s, accelerometer m/s^2); arrays are converted once, checked with
messages naming the field and the sample, and stored read-only so no stage can
mutate another stage's input.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray, as_float_array, check_finite, check_shape
from mocapkit.errors import DataError

# |q| must be within this of 1 for a stored orientation; looser than float32 storage
# error (~1e-7) and the 6 decimals of text exports, tight enough to catch scaled or
# non-normalised data.
_UNIT_NORM_TOLERANCE = 1e-3


def _frozen(arr: FloatArray) -> FloatArray:
    arr.setflags(write=False)
    return arr


def _check_time(time: FloatArray, name: str) -> None:
    check_shape(time, f"{name}.time", None)
    check_finite(time, f"{name}.time", "Timestamps must be finite seconds.")
    if time.size > 1:
        dt = np.diff(time)
        bad = np.flatnonzero(dt <= 0.0)
        if bad.size:
            i = int(bad[0])
            raise DataError(
                f"{name}.time: not strictly increasing at sample {i + 1} "
                f"({time[i]:.6f} s then {time[i + 1]:.6f} s; {bad.size} such steps). "
                "Sort the samples and drop duplicates before building the recording."
            )


def _interpolate_rows(t: FloatArray, x: FloatArray) -> FloatArray:
    """Linearly interpolate non-finite rows of x (N, k) over time; edges take the nearest value."""
    good = np.isfinite(x).all(axis=1)
    if good.all():
        return x
    if not good.any():
        raise DataError("cannot interpolate: no finite sample at all")
    out = x.copy()
    for c in range(x.shape[1]):
        out[~good, c] = np.interp(t[~good], t[good], x[good, c])
    return out


def _check_mag_gaps(mag: FloatArray, name: str, fix: str) -> None:
    """Magnetometer rows may be all-NaN (a gap: the filters propagate without the
    magnetometer there); a partly NaN row or an infinite value is an error."""
    gap: np.ndarray = np.asarray(np.isnan(mag).all(axis=1))
    bad = ~np.isfinite(mag) & ~gap[:, None]
    if bad.any():
        i, c = (int(v) for v in np.argwhere(bad)[0])
        raise DataError(
            f"{name}: non-finite value at sample {i}, column {c} "
            f"({int(bad.any(axis=1).sum())} bad samples); mark a magnetometer gap with all "
            f"three components NaN. {fix}"
        )


@dataclass(frozen=True)
class ImuRecording:
    """One sensor's raw samples, in the sensor frame.

    Attributes:
        time: (N,) sample times [s], strictly increasing.
        gyr: (N, 3) angular rate [rad/s].
        acc: (N, 3) specific force [m/s^2]; reads about +9.81 along the up axis at rest.
        mag: (N, 3) magnetic field (any consistent unit, uT when known) or None (6D).
            All-NaN rows mark magnetometer gaps (dropouts, or samples outside the
            magnetometer's own time range); the filters propagate without the
            magnetometer there (see ``mocapkit.imu.filters.base``).
        name: sensor label, used in every error message.
    """

    time: FloatArray
    gyr: FloatArray
    acc: FloatArray
    mag: FloatArray | None = None
    name: str = "imu"
    meta: dict[str, Any] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        n = self.name
        time = as_float_array(self.time, f"{n}.time")
        _check_time(time, n)
        fields: dict[str, FloatArray | None] = {}
        for key in ("gyr", "acc", "mag"):
            value = getattr(self, key)
            if value is None:
                fields[key] = None
                continue
            arr = as_float_array(value, f"{n}.{key}")
            check_shape(arr, f"{n}.{key}", time.shape[0], 3)
            fix = "Drop those samples or call ImuRecording.with_gaps_interpolated(...)."
            if key == "mag":
                _check_mag_gaps(arr, f"{n}.mag", fix)
            else:
                check_finite(arr, f"{n}.{key}", fix)
            fields[key] = _frozen(arr)
        if fields["gyr"] is None or fields["acc"] is None:
            raise DataError(f"{n}: gyr and acc are required")
        object.__setattr__(self, "time", _frozen(time))
        for key, value in fields.items():
            object.__setattr__(self, key, value)

    @classmethod
    def with_gaps_interpolated(
        cls,
        time: Any,
        gyr: Any,
        acc: Any,
        mag: Any = None,
        name: str = "imu",
        meta: dict[str, Any] | None = None,
    ) -> ImuRecording:
        """Build a recording, linearly interpolating non-finite samples (documented fallback).

        The number of repaired samples per field is stored in ``meta["interpolated"]``.
        """
        t = as_float_array(time, f"{name}.time")
        repaired: dict[str, int] = {}
        arrays: dict[str, FloatArray | None] = {}
        for key, value in (("gyr", gyr), ("acc", acc), ("mag", mag)):
            if value is None:
                arrays[key] = None
                continue
            arr = as_float_array(value, f"{name}.{key}")
            check_shape(arr, f"{name}.{key}", t.shape[0], 3)
            repaired[key] = int((~np.isfinite(arr).all(axis=1)).sum())
            arrays[key] = _interpolate_rows(t, arr)
        info = dict(meta or {})
        info["interpolated"] = repaired
        gyr_a, acc_a = arrays["gyr"], arrays["acc"]
        if gyr_a is None or acc_a is None:
            raise DataError(f"{name}: gyr and acc are required")
        return cls(t, gyr_a, acc_a, arrays["mag"], name=name, meta=info)

    @property
    def n_samples(self) -> int:
        return int(self.time.shape[0])

    @property
    def rate_hz(self) -> float:
        """Nominal sampling rate [Hz]: the inverse of the median sample interval."""
        if self.n_samples < 2:
            raise DataError(f"{self.name}: need at least 2 samples to know the sampling rate")
        return float(1.0 / np.median(np.diff(self.time)))

    @property
    def duration(self) -> float:
        return float(self.time[-1] - self.time[0]) if self.n_samples else 0.0

    @property
    def has_mag(self) -> bool:
        return self.mag is not None

    @property
    def mag_valid(self) -> np.ndarray:
        """(N,) bool: samples with a magnetometer reading (all False in 6D)."""
        if self.mag is None:
            return np.zeros(self.n_samples, dtype=bool)
        return np.asarray(np.isfinite(self.mag).all(axis=1))

    def slice(self, start: int, stop: int | None = None) -> ImuRecording:
        """Samples ``start:stop`` as a new recording (shares no writable memory)."""
        sl = slice(start, stop)
        mag = None if self.mag is None else self.mag[sl]
        return ImuRecording(
            self.time[sl], self.gyr[sl], self.acc[sl], mag, name=self.name, meta=dict(self.meta)
        )

    def without_mag(self) -> ImuRecording:
        """The same recording in 6D (magnetometer dropped)."""
        return ImuRecording(
            self.time, self.gyr, self.acc, None, name=self.name, meta=dict(self.meta)
        )


@dataclass(frozen=True)
class OrientationSeries:
    """Orientations ``q_world_sensor`` [w, x, y, z] over time.

    Rows may be all-NaN to mark a missing sample (a reference system that lost
    track); :attr:`valid` says which rows hold an orientation. Finite rows must be
    unit quaternions.
    """

    time: FloatArray
    quat: FloatArray
    name: str = "orientation"
    frame: str = "world"

    def __post_init__(self) -> None:
        n = self.name
        time = as_float_array(self.time, f"{n}.time")
        _check_time(time, n)
        quat = as_float_array(self.quat, f"{n}.quat")
        check_shape(quat, f"{n}.quat", time.shape[0], 4)
        finite = np.isfinite(quat)
        partial = finite.any(axis=1) & ~finite.all(axis=1)
        if partial.any():
            i = int(np.flatnonzero(partial)[0])
            raise DataError(
                f"{n}.quat: sample {i} is partly NaN ({quat[i]}); mark a missing sample with all "
                "four components NaN"
            )
        rows = finite.all(axis=1)
        norms = np.linalg.norm(quat[rows], axis=1)
        off = np.flatnonzero(np.abs(norms - 1.0) > _UNIT_NORM_TOLERANCE)
        if off.size:
            i = int(np.flatnonzero(rows)[off[0]])
            raise DataError(
                f"{n}.quat: sample {i} has norm {norms[off[0]]:.6f}, expected a unit quaternion "
                "[w, x, y, z]; normalise it (mocapkit.geometry.quat_normalize) or check the "
                "component order"
            )
        quat = quat.copy()
        quat[rows] /= np.linalg.norm(quat[rows], axis=1, keepdims=True)
        object.__setattr__(self, "time", _frozen(time))
        object.__setattr__(self, "quat", _frozen(quat))

    @property
    def valid(self) -> np.ndarray:
        """(N,) bool: rows that hold an orientation."""
        return np.asarray(np.isfinite(self.quat).all(axis=1))

    @property
    def n_samples(self) -> int:
        return int(self.time.shape[0])


@dataclass(frozen=True)
class PoseSeries:
    """Rigid-body poses over time: ``q_world_body`` [w, x, y, z] and ``p_world_body`` [m].

    The common currency between a body motion (segments) and what a sensor mounted
    on it experiences (the suit simulator), and between a robot and its end effector.
    """

    time: FloatArray
    quat: FloatArray
    pos: FloatArray
    name: str = "body"

    def __post_init__(self) -> None:
        ori = OrientationSeries(self.time, self.quat, name=self.name)
        pos = as_float_array(self.pos, f"{self.name}.pos")
        check_shape(pos, f"{self.name}.pos", ori.n_samples, 3)
        check_finite(pos, f"{self.name}.pos", "Positions must be finite metres.")
        object.__setattr__(self, "time", ori.time)
        object.__setattr__(self, "quat", ori.quat)
        object.__setattr__(self, "pos", _frozen(pos))

    @property
    def n_samples(self) -> int:
        return int(self.time.shape[0])


@dataclass(frozen=True)
class JointAngleSeries:
    """Joint coordinates over time: the meeting point of the IMU and marker pipelines.

    Attributes:
        time: (N,) [s].
        names: k coordinate names. Human joints use OpenSim's coordinate names
            (``hip_flexion_r``, ``knee_angle_r``, ``arm_flex_r``, ``elbow_flex_r``,
            ``pro_sup_r``...); robot joints use the robot model's joint names.
        values: (N, k) [rad] for rotational coordinates ([m] for translational ones).
            NaN marks a frame where a coordinate is unknown (a sensor dropped out).
    """

    time: FloatArray
    names: tuple[str, ...]
    values: FloatArray
    name: str = "joints"

    def __post_init__(self) -> None:
        time = as_float_array(self.time, f"{self.name}.time")
        _check_time(time, self.name)
        names = tuple(str(s) for s in self.names)
        if len(set(names)) != len(names):
            dup = sorted({s for s in names if names.count(s) > 1})
            raise DataError(f"{self.name}.names: duplicated coordinate name(s) {', '.join(dup)}")
        values = as_float_array(self.values, f"{self.name}.values")
        check_shape(values, f"{self.name}.values", time.shape[0], len(names))
        if np.isinf(values).any():
            i = int(np.argwhere(np.isinf(values))[0][0])
            raise DataError(f"{self.name}.values: infinite value at sample {i}")
        object.__setattr__(self, "time", _frozen(time))
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "values", _frozen(values))

    def column(self, name: str) -> FloatArray:
        """One coordinate over time; the error lists the available names."""
        if name not in self.names:
            raise DataError(
                f"{self.name}: no coordinate {name!r}; available: {', '.join(self.names)}"
            )
        return self.values[:, self.names.index(name)]

    def unit(self, name: str) -> str:
        """``"m"`` for a translational coordinate (``*_tx``, ``*_ty``, ``*_tz``), else
        ``"rad"``."""
        return "m" if name.endswith(("_tx", "_ty", "_tz")) else "rad"

    def to_dataframe(self, degrees: bool = False) -> Any:
        """A pandas DataFrame indexed by ``time_s``, one column per coordinate with its
        unit in the name (``knee_angle_r_rad``, ``pelvis_tx_m``; ``_deg`` with
        ``degrees``). Needs pandas."""
        try:
            import pandas as pd
        except ImportError as exc:
            from mocapkit.errors import MissingDependencyError

            raise MissingDependencyError("to_dataframe needs pandas: pip install pandas") from exc
        columns = {}
        for k, n in enumerate(self.names):
            unit = self.unit(n)
            values = self.values[:, k]
            if degrees and unit == "rad":
                unit, values = "deg", np.degrees(values)
            columns[f"{n}_{unit}"] = values
        return pd.DataFrame(columns, index=pd.Index(self.time, name="time_s"))

    @property
    def n_samples(self) -> int:
        return int(self.time.shape[0])
