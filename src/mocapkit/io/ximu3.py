"""Reader for x-IMU3 CSV exports (x-io Technologies): one directory per sensor.

Files used (time stamps in microseconds of the device clock):

- ``Inertial.csv``: ``Timestamp (us)``, gyroscope X/Y/Z (deg/s), accelerometer X/Y/Z (g);
  converted on read to rad/s and m/s^2 (standard gravity 9.80665 m/s^2 per g);
- ``Magnetometer.csv``: ``Timestamp (us)``, X/Y/Z (a.u., the device's normalised unit,
  kept as is), sampled at a lower rate (about 20 Hz) with its own time stamps;
- ``Quaternion.csv``: the device's own fusion, ``W, X, Y, Z``, in the device's NWU earth
  frame (x north, y west, z up), converted to ENU on read (a +90 deg turn about z).
- ``Command.json`` (optional): the sensor's name (``ping.name``).

The magnetometer is aligned to the inertial time stamps by linear interpolation per
component (honest but not free: the field is interpolated between real samples).
Inertial samples before the first or after the last magnetometer sample, or inside a
magnetometer dropout longer than ``max_mag_gap`` nominal intervals, get an all-NaN
row (a gap, which the filters bridge in 6D) instead of an extrapolated value.
What was done is recorded in ``recording.meta["mag_alignment"]``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import FileFormatError
from mocapkit.geometry import quat_from_axis_angle, quat_mul
from mocapkit.io._text_table import parse_rows, read_text
from mocapkit.series import ImuRecording, OrientationSeries

STANDARD_GRAVITY = 9.80665  # [m/s^2 per g]
INERTIAL_COLUMNS = [
    "Timestamp (us)",
    "Gyroscope X (deg/s)",
    "Gyroscope Y (deg/s)",
    "Gyroscope Z (deg/s)",
    "Accelerometer X (g)",
    "Accelerometer Y (g)",
    "Accelerometer Z (g)",
]
MAG_COLUMNS = ["Timestamp (us)", "X (a.u.)", "Y (a.u.)", "Z (a.u.)"]
QUAT_COLUMNS = ["Timestamp (us)", "W", "X", "Y", "Z"]
# q_ENU_NWU: a +90 deg turn about the common up axis takes north (NWU x) to ENU y.
Q_ENU_NWU = quat_from_axis_angle([0.0, 0.0, 1.0], np.pi / 2)


def _read_table(path: Path, columns: list[str]) -> FloatArray:
    lines = read_text(path)
    if not lines:
        raise FileFormatError(f"{path}: empty file")
    header = [c.strip() for c in lines[0].split(",")]
    if header != columns:
        raise FileFormatError(
            f"{path}: header {header} does not match the x-IMU3 export {columns}; "
            "is this an x-IMU3 GUI CSV export?"
        )
    data = parse_rows(path, lines[1:], 2, columns)
    t = data[:, 0]
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise FileFormatError(
            f"{path}: time stamps not increasing at data row {i} (line {i + 2}: "
            f"{t[i - 1]:.0f} us then {t[i]:.0f} us); sort the rows and drop duplicates"
        )
    return data


def _is_serial(word: str) -> bool:
    return len(word) == 8 and all(c in "0123456789ABCDEFabcdef" for c in word)


def sensor_name(directory: str | Path) -> str:
    """The name in ``Command.json`` (``ping.name``), else the directory name without the
    serial number and interface suffix (``"Left Foot 64F0EBCE (UDP)"`` -> ``"Left Foot"``)."""
    d = Path(directory)
    cmd = d / "Command.json"
    if cmd.is_file():
        try:
            for entry in json.loads(cmd.read_text()):
                name = entry.get("ping", {}).get("name")
                if name:
                    return str(name)
        except (json.JSONDecodeError, AttributeError):
            pass
    parts = d.name.split(" ")
    while len(parts) > 1 and (parts[-1].startswith("(") or _is_serial(parts[-1])):
        parts.pop()
    return " ".join(parts)


def align_mag(
    t_inertial: FloatArray, t_mag: FloatArray, mag: FloatArray, max_gap: float = 2.5
) -> tuple[FloatArray, int]:
    """Interpolate (M, 3) magnetometer samples at (N,) inertial times.

    Returns the (N, 3) field (all-NaN rows outside the magnetometer's time range or in
    dropouts longer than ``max_gap`` median intervals) and the number of such rows.
    """
    out = np.column_stack([np.interp(t_inertial, t_mag, mag[:, k]) for k in range(3)])
    outside = (t_inertial < t_mag[0]) | (t_inertial > t_mag[-1])
    if t_mag.size > 1:
        step = np.diff(t_mag)
        limit = max_gap * float(np.median(step))
        j = np.clip(np.searchsorted(t_mag, t_inertial), 1, t_mag.size - 1)
        outside |= (t_mag[j] - t_mag[j - 1]) > limit
    out[outside] = np.nan
    return out, int(outside.sum())


def read_ximu3_sensor(
    directory: str | Path, name: str | None = None, max_mag_gap: float = 2.5
) -> ImuRecording:
    """One sensor directory -> :class:`ImuRecording` (SI units; magnetometer in a.u.)."""
    d = Path(directory)
    inertial = d / "Inertial.csv"
    if not inertial.is_file():
        raise FileFormatError(f"{d}: no Inertial.csv; is this an x-IMU3 sensor export directory?")
    data = _read_table(inertial, INERTIAL_COLUMNS)
    time = data[:, 0] * 1e-6
    gyr = np.radians(data[:, 1:4])
    acc = data[:, 4:7] * STANDARD_GRAVITY
    label = name or sensor_name(d)
    meta: dict[str, object] = {"source": str(d), "format": "x-IMU3", "mag_unit": "a.u."}
    mag = None
    mag_file = d / "Magnetometer.csv"
    if mag_file.is_file():
        m = _read_table(mag_file, MAG_COLUMNS)
        mag, n_gap = align_mag(time, m[:, 0] * 1e-6, m[:, 1:4], max_mag_gap)
        rate = 1.0 / float(np.median(np.diff(m[:, 0] * 1e-6))) if len(m) > 1 else float("nan")
        meta["mag_alignment"] = (
            f"linear interpolation of {len(m)} Magnetometer.csv samples ({rate:.1f} Hz) onto "
            f"the Inertial.csv time stamps; {n_gap} samples outside its time range or in "
            f"dropouts longer than {max_mag_gap:g} intervals are gaps (NaN)"
        )
    return ImuRecording(time, gyr, acc, mag, name=label, meta=meta)


def read_ximu3_quaternion(directory: str | Path, name: str | None = None) -> OrientationSeries:
    """The device's own orientation (``Quaternion.csv``) as ``q_world_sensor`` in ENU."""
    d = Path(directory)
    path = d / "Quaternion.csv"
    if not path.is_file():
        raise FileFormatError(f"{d}: no Quaternion.csv in this x-IMU3 export")
    data = _read_table(path, QUAT_COLUMNS)
    q_enu = quat_mul(Q_ENU_NWU, data[:, 1:5])
    label = name or sensor_name(d)
    return OrientationSeries(data[:, 0] * 1e-6, q_enu, name=f"{label}.device", frame="ENU")


def is_ximu3_sensor(directory: str | Path) -> bool:
    return (Path(directory) / "Inertial.csv").is_file()


def ximu3_sensor_dirs(directory: str | Path) -> list[Path]:
    """Sensor sub-directories (those holding an Inertial.csv), sorted by name."""
    d = Path(directory)
    if not d.is_dir():
        raise FileFormatError(f"{d}: not a directory")
    return sorted(p for p in d.iterdir() if p.is_dir() and is_ximu3_sensor(p))


def read_ximu3_directory(directory: str | Path) -> dict[str, ImuRecording]:
    """Every sensor of a multi-sensor x-IMU3 export: ``{sensor name: recording}``.

    Each sensor keeps its own time stamps (the device clocks; no resampling here).
    """
    d = Path(directory)
    dirs = ximu3_sensor_dirs(d)
    if not dirs:
        raise FileFormatError(
            f"{d}: no sensor directory with an Inertial.csv; expected an x-IMU3 export with "
            "one directory per sensor"
        )
    out: dict[str, ImuRecording] = {}
    for sub in dirs:
        rec = read_ximu3_sensor(sub)
        if rec.name in out:
            raise FileFormatError(f"{d}: two sensors are named {rec.name!r} ({sub.name})")
        out[rec.name] = rec
    return out
