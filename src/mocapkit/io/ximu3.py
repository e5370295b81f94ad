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
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import DataError, FileFormatError
from mocapkit.geometry import quat_from_axis_angle, quat_mul
from mocapkit.io._text_table import iter_csv_blocks
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


def _blocks(path: Path, columns: list[str], rows: int = 50_000) -> Iterator[FloatArray]:
    """An x-IMU3 CSV's rows, ``rows`` at a time, time stamps checked increasing across
    blocks (the error names the row and line)."""
    last: float | None = None
    row0 = 0
    blocks = iter_csv_blocks(path, columns, rows, what="x-IMU3 export",
                             hint="; is this an x-IMU3 GUI CSV export?")  # fmt: skip
    for line, data in blocks:
        t = data[:, 0] if last is None else np.concatenate([[last], data[:, 0]])
        bad = np.flatnonzero(np.diff(t) <= 0)
        if bad.size:
            k = int(bad[0]) + (1 if last is None else 0)  # index in this block
            raise FileFormatError(
                f"{path}: time stamps not increasing at data row {row0 + k} (line "
                f"{line + k}: {t[int(bad[0])]:.0f} us then {data[k, 0]:.0f} us); sort the "
                "rows and drop duplicates"
            )
        last = float(data[-1, 0])
        row0 += len(data)
        yield data


def _read_table(path: Path, columns: list[str]) -> FloatArray:
    return np.concatenate(list(_blocks(path, columns)))


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


def iter_ximu3_sensor(
    directory: str | Path, name: str | None = None, rows: int = 100_000,
    max_mag_gap: float = 2.5,
) -> Iterator[ImuRecording]:  # fmt: skip
    """:func:`read_ximu3_sensor` in pieces of ``rows`` inertial samples, read as it goes
    (an hour's export in bounded memory); the magnetometer is aligned piece by piece from
    the samples either side of each piece, so the pieces give the whole reader's numbers."""
    d = Path(directory)
    inertial = d / "Inertial.csv"
    if not inertial.is_file():
        raise FileFormatError(f"{d}: no Inertial.csv; is this an x-IMU3 sensor export directory?")
    label = name or sensor_name(d)
    meta: dict[str, object] = {"source": str(d), "format": "x-IMU3", "mag_unit": "a.u."}
    mag_file = d / "Magnetometer.csv"
    mag = _MagCursor(mag_file, rows, max_mag_gap) if mag_file.is_file() else None
    for data in _blocks(inertial, INERTIAL_COLUMNS, rows):
        time = data[:, 0] * 1e-6
        m = None if mag is None else mag.at(time)
        yield ImuRecording(time, np.radians(data[:, 1:4]), data[:, 4:7] * STANDARD_GRAVITY, m,
                           name=label, meta=dict(meta))  # fmt: skip


class _MagCursor:
    """Magnetometer.csv read forwards, block by block, aligned (as :func:`align_mag`) onto
    increasing inertial times; the dropout limit uses the whole file's median interval (a
    first pass over it)."""

    def __init__(self, path: Path, rows: int, max_gap: float) -> None:
        steps: list[FloatArray] = []
        last: float | None = None
        self.first = self.last = float("nan")
        for data in _blocks(path, MAG_COLUMNS, rows):
            t = data[:, 0] * 1e-6
            steps.append(np.diff(t if last is None else np.concatenate([[last], t])))
            if last is None:
                self.first = float(t[0])
            last = float(t[-1])
        self.last = float(last) if last is not None else float("nan")
        all_steps = np.concatenate(steps) if steps else np.zeros(0)
        self.limit = max_gap * float(np.median(all_steps)) if all_steps.size else np.inf
        self._blocks = _blocks(path, MAG_COLUMNS, rows)
        self._t = np.zeros(0)
        self._m = np.zeros((0, 3))
        self._done = False

    def at(self, t: FloatArray) -> FloatArray:
        """The field at the inertial times ``t`` (NaN outside the file or in dropouts)."""
        while not self._done and (self._t.size == 0 or self._t[-1] < t[-1]):
            block = next(self._blocks, None)
            if block is None:
                self._done = True
                break
            self._t = np.concatenate([self._t, block[:, 0] * 1e-6])
            self._m = np.concatenate([self._m, block[:, 1:4]])
        out, _ = align_mag(t, self._t, self._m, np.inf)
        outside = (t < self.first) | (t > self.last)
        if self._t.size > 1:
            j = np.clip(np.searchsorted(self._t, t), 1, self._t.size - 1)
            outside |= (self._t[j] - self._t[j - 1]) > self.limit
        out[outside] = np.nan
        keep = max(0, int(np.searchsorted(self._t, t[-1])) - 1)  # the sample before the
        self._t, self._m = self._t[keep:], self._m[keep:]  # next piece's first time
        return out


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


def is_ximu3_export(path: str | Path) -> bool:
    """A directory of one x-IMU3 sensor's export, or one holding a sub-directory per
    sensor."""
    p = Path(path)
    return p.is_dir() and (is_ximu3_sensor(p) or bool(ximu3_sensor_dirs(p)))


def ximu3_sensors(path: str | Path) -> dict[str, Path]:
    """``{sensor name: directory}`` of an x-IMU3 export (one sensor's directory, or one
    holding a sub-directory per sensor); two sensors of one name are refused."""
    p = Path(path)
    out: dict[str, Path] = {}
    for d in [p] if is_ximu3_sensor(p) else ximu3_sensor_dirs(p):
        name = sensor_name(d)
        if name in out:
            raise DataError(f"{p}: two sensors are named {name!r} ({out[name].name}, {d.name})")
        out[name] = d
    return out


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
