"""TRC marker files (OpenSim, Motion Analysis, Cortex): read and write.

Read: the declared ``Units`` are converted to metres, the axes are kept as in the
file (OpenSim's TRC files are y-up: ``meta["up_axis"] = "y"`` is only a hint, the
reconstruction checks it against the static trial), empty cells become NaN.
Write: millimetres, tab-separated, the layout OpenSim reads.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.errors import FileFormatError
from mocapkit.io.units import length_scale
from mocapkit.markers.trajectories import MarkerTrajectories

_HEADER_KEYS = (
    "DataRate",
    "CameraRate",
    "NumFrames",
    "NumMarkers",
    "Units",
    "OrigDataRate",
    "OrigDataStartFrame",
    "OrigNumFrames",
)


def _cell_float(text: str) -> float:
    text = text.strip()
    if not text or text.lower() in ("nan", "-nan"):
        return float("nan")
    return float(text)


def read_trc(path: str | Path, units: str | None = None) -> MarkerTrajectories:
    """Read a TRC file.

    Args:
        path: the ``.trc`` file.
        units: override the file's declared length unit (``"mm"``, ``"cm"``, ``"m"``).

    Returns:
        Trajectories in metres, file axes; ``meta`` holds ``source``, ``units`` (declared),
        ``rate_hz`` and ``up_axis="y"`` (the TRC convention; checked later).
    """
    p = Path(path)
    try:
        lines = p.read_text(errors="strict").splitlines()
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{p}: not a text TRC file ({exc})") from exc
    if len(lines) < 5 or not lines[0].startswith("PathFileType"):
        raise FileFormatError(
            f"{p}: not a TRC file (the first line should start with 'PathFileType')"
        )
    keys = [k.strip() for k in lines[1].split("\t")]
    values = [v.strip() for v in lines[2].split("\t")]
    header = dict(zip(keys, values, strict=False))
    for key in ("DataRate", "NumMarkers", "Units"):
        if key not in header or not header[key]:
            raise FileFormatError(f"{p}: header field {key!r} missing on line 3")
    try:
        rate = float(header["DataRate"])
        n_markers = int(header["NumMarkers"])
    except ValueError as exc:
        raise FileFormatError(f"{p}: header line 3: {exc}") from exc
    scale = length_scale(units or header["Units"], f"{p}: Units")
    label_cells = lines[3].split("\t")
    if len(label_cells) < 2 or label_cells[0].strip() != "Frame#":
        raise FileFormatError(f"{p}: line 4 should start with 'Frame#\\tTime'")
    names = [c.strip() for c in label_cells[2:] if c.strip()]
    if len(names) != n_markers:
        raise FileFormatError(
            f"{p}: header says NumMarkers={n_markers} but line 4 names {len(names)} markers"
        )
    rows = [line.split("\t") for line in lines[5:] if line.strip()]
    time = np.empty(len(rows))
    pos = np.full((len(rows), n_markers, 3), np.nan)
    for i, cells in enumerate(rows):
        try:
            time[i] = float(cells[1])
            coords = [_cell_float(c) for c in cells[2 : 2 + 3 * n_markers]]
        except (ValueError, IndexError) as exc:
            raise FileFormatError(f"{p}: data row {i} (file line {i + 6}): {exc}") from exc
        coords += [float("nan")] * (3 * n_markers - len(coords))
        pos[i] = np.asarray(coords).reshape(n_markers, 3)
    meta: dict[str, Any] = {
        "source": str(p),
        "format": "trc",
        "units": units or header["Units"],
        "rate_hz": rate,
        "up_axis": "y",
        "up_axis_source": "TRC convention (OpenSim)",
    }
    return MarkerTrajectories(time, pos * scale, tuple(names), meta=meta)


def write_trc(path: str | Path, trajectories: MarkerTrajectories, units: str = "mm") -> Path:
    """Write trajectories (metres) as a TRC file in ``units`` (NaN -> empty cells)."""
    p = Path(path)
    scale = 1.0 / length_scale(units, "units")
    traj = trajectories
    rate = traj.rate_hz if traj.n_frames > 1 else float(traj.meta.get("rate_hz", 0.0))
    out = [
        f"PathFileType\t4\t(X/Y/Z)\t{p.name}",
        "\t".join(_HEADER_KEYS),
        "\t".join(
            [
                f"{rate:.6g}",
                f"{rate:.6g}",
                str(traj.n_frames),
                str(traj.n_markers),
                units,
                f"{rate:.6g}",
                "1",
                str(traj.n_frames),
            ]
        ),
        "\t".join(["Frame#", "Time", *[f"{n}\t\t" for n in traj.names]]),
        "\t".join(["", "", *[f"X{i + 1}\tY{i + 1}\tZ{i + 1}" for i in range(traj.n_markers)]]),
        "",
    ]
    data = traj.positions * scale
    for f in range(traj.n_frames):
        cells = [str(f + 1), f"{traj.time[f]:.6f}"]
        for v in data[f].reshape(-1):
            cells.append("" if not np.isfinite(v) else f"{v:.6f}")
        out.append("\t".join(cells))
    p.write_text("\n".join(out) + "\n")
    return p
