"""A plain CSV format for one IMU, with declared units (read and write).

Example (what :func:`write_imu_csv` produces)::

    # mocapkit imu csv v1
    # name: pelvis
    time [s],gyr_x [deg/s],gyr_y [deg/s],gyr_z [deg/s],acc_x [g],acc_y [g],acc_z [g]
    0,0.5,-1.2,0.2,0.01,0.02,0.99

(with ``mag_x [uT],mag_y [uT],mag_z [uT]`` columns in 9D).

Rules:

- Lines starting with ``#`` are comments; ``# name: <label>`` names the sensor.
- The first other line holds the column labels, each ``<column> [<unit>]``. Columns
  ``time``, ``gyr_x/y/z`` and ``acc_x/y/z`` are required, ``mag_x/y/z`` optional (6D
  without them); any order; other columns are ignored. Every column needs a unit.
- Units, converted on read to SI: time ``s``, ``ms``, ``us``; gyroscope ``rad/s``,
  ``deg/s``; accelerometer ``m/s^2``, ``g`` (9.80665 m/s^2); magnetometer ``uT``,
  ``nT``, ``mT``, ``G`` (gauss) -> uT, or ``a.u.`` (kept as is).
- An empty magnetometer row (all three cells empty) is a gap (all-NaN row).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mocapkit.errors import FileFormatError
from mocapkit.io._text_table import parse_rows, read_text
from mocapkit.series import ImuRecording

STANDARD_GRAVITY = 9.80665  # [m/s^2 per g]
MAGIC = "# mocapkit imu csv v1"

UNITS: dict[str, dict[str, float]] = {
    "time": {"s": 1.0, "ms": 1e-3, "us": 1e-6},
    "gyr": {"rad/s": 1.0, "deg/s": np.pi / 180.0},
    "acc": {"m/s^2": 1.0, "m/s2": 1.0, "g": STANDARD_GRAVITY},
    "mag": {"ut": 1.0, "nt": 1e-3, "mt": 1e3, "g": 100.0, "gauss": 100.0, "a.u.": 1.0},
}
_REQUIRED = ["time", "gyr_x", "gyr_y", "gyr_z", "acc_x", "acc_y", "acc_z"]
_MAG = ["mag_x", "mag_y", "mag_z"]


def _parse_label(path: Path, label: str, lineno: int) -> tuple[str, str]:
    text = label.strip()
    if "[" not in text or not text.endswith("]"):
        raise FileFormatError(
            f"{path}: line {lineno}: column {text!r} has no unit; write it as "
            "'<name> [<unit>]', e.g. 'gyr_x [deg/s]'"
        )
    name, unit = text[:-1].split("[", 1)
    return name.strip().lower(), unit.strip()


def _factor(path: Path, column: str, unit: str) -> float:
    kind = column.split("_")[0]
    table = UNITS[kind]
    key = unit.lower() if kind == "mag" else unit
    if key not in table:
        raise FileFormatError(
            f"{path}: column {column!r} has unit {unit!r}; supported: {', '.join(table)}"
        )
    return table[key]


def read_imu_csv(path: str | Path, name: str | None = None) -> ImuRecording:
    """Read one IMU from the plain CSV format (see the module docstring)."""
    p = Path(path)
    lines = read_text(p)
    label = name
    k = 0
    while k < len(lines) and (lines[k].startswith("#") or not lines[k].strip()):
        comment = lines[k].lstrip("#").strip()
        if comment.lower().startswith("name:") and label is None:
            label = comment.split(":", 1)[1].strip()
        k += 1
    if k >= len(lines):
        raise FileFormatError(f"{p}: no column labels (expected 'time [s],gyr_x [rad/s],...')")
    parsed = [_parse_label(p, c, k + 1) for c in lines[k].split(",")]
    columns = [c for c, _ in parsed]
    missing = [c for c in _REQUIRED if c not in columns]
    if missing:
        raise FileFormatError(f"{p}: missing column(s) {', '.join(missing)}")
    has_mag = [c in columns for c in _MAG]
    if any(has_mag) and not all(has_mag):
        raise FileFormatError(f"{p}: give all of mag_x, mag_y, mag_z or none of them")
    if len(set(columns)) != len(columns):
        raise FileFormatError(f"{p}: duplicated column names {columns}")
    data = parse_rows(p, lines[k + 1 :], k + 2, columns, allow_empty=True)
    wanted = _REQUIRED + (_MAG if all(has_mag) else [])
    values = {}
    for c in wanted:
        i = columns.index(c)
        col = data[:, i] * _factor(p, c, parsed[i][1])
        if c not in _MAG:
            bad = np.flatnonzero(~np.isfinite(col))
            if bad.size:
                raise FileFormatError(
                    f"{p}: column {c!r} is empty or not finite at data row {bad[0]} "
                    f"(line {k + 2 + int(bad[0])})"
                )
        values[c] = col
    mag = None
    mag_unit = None
    if all(has_mag):
        mag = np.column_stack([values[c] for c in _MAG])
        unit = parsed[columns.index("mag_x")][1]
        mag_unit = "a.u." if unit.lower() == "a.u." else "uT"
    meta: dict[str, object] = {"source": str(p), "format": "mocapkit imu csv"}
    if mag_unit:
        meta["mag_unit"] = mag_unit
    return ImuRecording(
        values["time"],
        np.column_stack([values[c] for c in _REQUIRED[1:4]]),
        np.column_stack([values[c] for c in _REQUIRED[4:7]]),
        mag,
        name=label or p.stem,
        meta=meta,
    )


def write_imu_csv(path: str | Path, rec: ImuRecording, mag_unit: str | None = None) -> Path:
    """Write ``rec`` in SI units (magnetometer in ``mag_unit``, default from
    ``rec.meta["mag_unit"]`` or uT). Gaps in the magnetometer are written as empty cells."""
    p = Path(path)
    unit = mag_unit or str(rec.meta.get("mag_unit", "uT"))
    header = [
        "time [s]",
        *(f"gyr_{a} [rad/s]" for a in "xyz"),
        *(f"acc_{a} [m/s^2]" for a in "xyz"),
    ]
    cols = [rec.time[:, None], rec.gyr, rec.acc]
    if rec.mag is not None:
        header += [f"mag_{a} [{unit}]" for a in "xyz"]
        cols.append(rec.mag)
    table = np.hstack(cols)
    lines = [MAGIC, f"# name: {rec.name}", ",".join(header)]
    for row in table:
        lines.append(",".join("" if np.isnan(v) else f"{v:.10g}" for v in row))
    p.write_text("\n".join(lines) + "\n")
    return p
