"""The common path in a few calls, importable from the top level (``mocapkit.reconstruct``,
``mocapkit.read_c3d``, ...). Every option is keyword-only; units are SI and radians.

>>> import mocapkit
>>> rec = mocapkit.reconstruct("walk.trc", height_m=1.80)        # doctest: +SKIP
>>> rec.angles.to_dataframe(degrees=True).head()                  # doctest: +SKIP
>>> imu = mocapkit.read_imu("thigh.csv")["thigh"]                 # doctest: +SKIP
>>> q = mocapkit.make_filter("polaris", imu.rate_hz).run_recording(imu)  # doctest: +SKIP

``import mocapkit`` stays light: each name imports its module when first used.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.series import JointAngleSeries


@dataclass(frozen=True)
class Reconstruction:
    """What :func:`reconstruct` returns.

    Attributes:
        angles: the joint angles (OpenSim coordinate names; [rad], [m] for ``*_t?``);
            ``angles.to_dataframe()`` for a table.
        rms_marker_error_m: RMS distance of the tracked model markers to the captured ones.
        result: everything the reconstruction computed (bounds, model markers, levels).
        subject: the scaled model and its marker set.
        cleaning: what was done to the markers before (gaps, filtering, axes).
        warnings: the doubts the run raised, as sentences.
    """

    angles: JointAngleSeries
    rms_marker_error_m: float
    result: Any
    subject: Any
    cleaning: Any
    warnings: tuple[str, ...]

    def to_dataframe(self, degrees: bool = False) -> Any:
        """``angles.to_dataframe`` (pandas)."""
        return self.angles.to_dataframe(degrees=degrees)


def reconstruct(
    trial: str | Path,
    *,
    static: str | Path | None = None,
    markerset: str | Path | None = None,
    height_m: float | None = None,
    mass_kg: float | None = None,
    method: str = "osc",
    start_s: float | None = None,
    end_s: float | None = None,
) -> Reconstruction:
    """Joint angles from a marker trial (C3D or TRC), as ``mocapkit markers reconstruct``:
    by direct marker control (``method="osc"``, the paper) or least-squares IK (``"ik"``).

    ``height_m`` None: estimated from the markers (warned); ``markerset`` None: chosen
    from the trial's labels (or refused with the markers named)."""
    import logging

    from mocapkit.markers.reconstruct import ReconstructionOptions, run

    warned: list[str] = []

    class _Collect(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            if record.levelno >= logging.WARNING:
                warned.append(record.getMessage())

    handler = _Collect()
    logger = logging.getLogger("mocapkit")
    logger.addHandler(handler)
    try:
        opts = ReconstructionOptions(method=method, start_s=start_s, end_s=end_s)  # type: ignore[arg-type]
        result, subject, cleaning = run(trial, static, markerset, height_m, mass_kg, opts)
    finally:
        logger.removeHandler(handler)
    keep = [k for k in range(len(result.coordinate_names))
            if np.isfinite(result.coordinates[:, k]).any()]  # fmt: skip
    angles = JointAngleSeries(
        result.time,
        tuple(result.coordinate_names[k] for k in keep),
        result.coordinates[:, keep],
        name=Path(trial).stem,
    )
    rms = result.frame_rms(result.tracked)
    seen = rms[rms == rms]
    rms_m = float(seen.mean()) if seen.size else float("nan")
    return Reconstruction(angles, rms_m, result, subject, cleaning, tuple(warned))


def read_c3d(path: str | Path, *, units: str | None = None) -> Any:
    """Marker trajectories [m] of a C3D file (analogs, force plates and events kept in
    ``meta["c3d"]``)."""
    from mocapkit.io.c3d import read_c3d as _read

    return _read(path, units=units)


def read_trc(path: str | Path, *, units: str | None = None) -> Any:
    """Marker trajectories [m] of a TRC file (OpenSim's variants included)."""
    from mocapkit.io.trc import read_trc as _read

    return _read(path, units=units)


def read_imu(path: str | Path) -> dict[str, Any]:
    """Every sensor's IMU recording in a file or directory (mocapkit CSV, BROAD, x-IMU3,
    Xsens): ``{name: ImuRecording}`` [rad/s, m/s^2, uT]."""
    from mocapkit.io.imu_files import read_imu_recordings

    return read_imu_recordings(path)


def make_filter(name: str, rate_hz: float, **params: Any) -> Any:
    """An orientation filter (``polaris``, ``polaris-body``, ``bachmann``, ``miller``)."""
    from mocapkit.imu.filters import make_filter as _make

    return _make(name, rate_hz, **params)


__all__ = ["Reconstruction", "make_filter", "read_c3d", "read_imu", "read_trc", "reconstruct"]
