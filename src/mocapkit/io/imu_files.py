"""Open any supported IMU recording by path: ``{sensor name: ImuRecording}``.

- ``*.hdf5``: a BROAD trial (one sensor);
- ``*.csv``: the plain CSV format (:mod:`mocapkit.io.imu_csv`, one sensor);
- a directory with ``Inertial.csv``: one x-IMU3 sensor; a directory of such
  directories: a multi-sensor x-IMU3 export;
- ``MT_*.txt`` or a directory of them: Xsens MT Manager exports (only usable by the
  filters when they include the gyroscope).

:func:`read_device_orientations` returns the orientations the devices computed
themselves (x-IMU3 ``Quaternion.csv``, Xsens matrices), where the format has them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mocapkit.errors import FileFormatError
from mocapkit.io.broad import read_broad_trial
from mocapkit.io.imu_csv import read_imu_csv
from mocapkit.io.ximu3 import (
    is_ximu3_sensor,
    read_ximu3_directory,
    read_ximu3_quaternion,
    read_ximu3_sensor,
    ximu3_sensor_dirs,
)
from mocapkit.io.xsens import read_xsens_directory, read_xsens_export
from mocapkit.series import ImuRecording, OrientationSeries

_FORMATS = (
    "a BROAD .hdf5 trial, a mocapkit .csv, an x-IMU3 export directory, or Xsens MT_*.txt exports"
)


def _is_xsens_dir(p: Path) -> bool:
    return p.is_dir() and any(p.glob("MT_*.txt"))


#: [rad/s] faster than any human segment turns (2000 deg/s, a MEMS gyroscope's range):
#: readings above it are almost surely deg/s.
MAX_PLAUSIBLE_GYR = 35.0
#: [m/s^2] the median norm of a body-worn accelerometer is gravity, 9.81; near 1 it is in g.
G_UNITS_BELOW = 3.0


class UnitWarning(UserWarning):
    """A recording's values look like another unit than the one its format promises."""


def check_units(rec: ImuRecording) -> None:
    """Warn when the gyroscope looks like deg/s or the accelerometer like g (naming the
    column, the figure and the fix); the values are left as they are."""
    import warnings

    gyr = np.abs(rec.gyr)
    if gyr.size and float(gyr.max()) > MAX_PLAUSIBLE_GYR:
        k, axis = np.unravel_index(int(np.argmax(gyr)), gyr.shape)
        warnings.warn(
            f"{rec.name}: gyr column {'xyz'[axis]} reaches {float(gyr.max()):.4g} rad/s at sample "
            f"{k} (over {MAX_PLAUSIBLE_GYR:g} rad/s = 2000 deg/s): the file's gyroscope looks "
            "like deg/s; convert it to rad/s (multiply by pi/180) before using these results",
            UnitWarning,
            stacklevel=3,
        )
    norms = np.linalg.norm(rec.acc, axis=1)
    if norms.size and float(np.median(norms)) < G_UNITS_BELOW:
        warnings.warn(
            f"{rec.name}: acc's median norm is {float(np.median(norms)):.3g} (gravity is 9.81 "
            "m/s^2): the accelerometer looks like g; multiply by 9.81 before using these results",
            UnitWarning,
            stacklevel=3,
        )


def read_imu_recordings(path: str | Path) -> dict[str, ImuRecording]:
    """Every sensor in ``path`` (see the module docstring for the formats); a gyroscope
    that looks like deg/s or an accelerometer like g is warned about (:func:`check_units`)."""
    recs = _read_imu_recordings(path)
    for rec in recs.values():
        check_units(rec)
    return recs


def _read_imu_recordings(path: str | Path) -> dict[str, ImuRecording]:
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such file or directory")
    if p.is_file():
        suffix = p.suffix.lower()
        if suffix in (".hdf5", ".h5"):
            trial = read_broad_trial(p)
            return {trial.name: trial.imu}
        if suffix == ".csv":
            rec = read_imu_csv(p)
            return {rec.name: rec}
        if suffix == ".txt" and p.name.startswith("MT_"):
            e = read_xsens_export(p)
            return {e.name: e.to_recording()}
        raise FileFormatError(f"{p}: unknown file type; expected {_FORMATS}")
    if is_ximu3_sensor(p):
        rec = read_ximu3_sensor(p)
        return {rec.name: rec}
    if ximu3_sensor_dirs(p):
        return read_ximu3_directory(p)
    if _is_xsens_dir(p):
        return {k: e.to_recording() for k, e in read_xsens_directory(p).items()}
    raise FileFormatError(f"{p}: no recording found; expected {_FORMATS}")


def read_device_orientations(path: str | Path) -> dict[str, OrientationSeries]:
    """The devices' own orientation estimates (x-IMU3 and Xsens exports), ENU."""
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such file or directory")
    if p.is_file() and p.name.startswith("MT_") and p.suffix.lower() == ".txt":
        e = read_xsens_export(p)
        return {e.name: e.orientation}
    if p.is_dir() and is_ximu3_sensor(p):
        ori = read_ximu3_quaternion(p)
        return {ori.name.removesuffix(".device"): ori}
    if p.is_dir() and ximu3_sensor_dirs(p):
        out = {}
        for sub in ximu3_sensor_dirs(p):
            ori = read_ximu3_quaternion(sub)
            out[ori.name.removesuffix(".device")] = ori
        return out
    if _is_xsens_dir(p):
        return {k: e.orientation for k, e in read_xsens_directory(p).items()}
    raise FileFormatError(
        f"{p}: no device orientations here (x-IMU3 Quaternion.csv or Xsens exports only)"
    )
