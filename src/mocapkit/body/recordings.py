"""Sensor orientations (and raw samples) from a body recording, whatever its format: the
one place ``body angles``, ``body identify``, ``retarget`` and the benchmarks read them.

Formats: ``qmt-mat`` (qmt full-body .mat: raw samples and the device quaternions),
``opensense-sto`` (OpenSense quaternion tables: orientations only), ``device`` (x-IMU3 or
Xsens export directories: the devices' orientations and raw samples).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from mocapkit.errors import ConfigError
from mocapkit.series import ImuRecording, OrientationSeries

FORMATS = ("auto", "qmt-mat", "opensense-sto", "device")
DEVICE = "device"  # as a filter name: the devices' own orientations


def recording_format(path: Path, fmt: str = "auto") -> str:
    """``fmt``, or the format told from the name when ``"auto"``."""
    if fmt != "auto":
        return fmt
    if path.suffix.lower() == ".mat":
        return "qmt-mat"
    if path.suffix.lower() in (".sto", ".mot"):
        return "opensense-sto"
    if path.is_dir():
        return "device"
    raise ConfigError(
        f"{path}: cannot tell the recording format from its name; give --format "
        f"({', '.join(FORMATS[1:])})"
    )


def _exists(path: Path) -> None:
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file or directory")


def read_raw(path: Path, fmt: str) -> dict[str, ImuRecording]:
    """The raw samples of every sensor (``fmt`` already resolved)."""
    if fmt == "qmt-mat":
        from mocapkit.io.qmt_mat import read_qmt_mat

        return dict(read_qmt_mat(path).imu)
    if fmt == "opensense-sto":
        raise ConfigError(f"{path}: an orientation table has no raw samples to filter")
    from mocapkit.io.imu_files import read_imu_recordings

    return read_imu_recordings(path)


def run_filter(
    recordings: Mapping[str, ImuRecording], filter_name: str, mode: str
) -> dict[str, OrientationSeries]:
    """A mocapkit filter (9D or 6D) on every sensor's raw samples."""
    from mocapkit.imu.filters.base import make_filter

    return {
        name: make_filter(filter_name, rec.rate_hz).run_recording(rec, use_mag=mode == "9d")
        for name, rec in recordings.items()
    }


def load_orientations(
    path: Path, fmt: str = "auto", filter_name: str | None = None, mode: str = "9d"
) -> dict[str, OrientationSeries]:
    """Sensor orientations from a recording: its own, or those of a mocapkit filter run on
    its raw samples."""
    _exists(path)
    fmt = recording_format(path, fmt)
    if filter_name is not None:
        return run_filter(read_raw(path, fmt), filter_name, mode)
    if fmt == "qmt-mat":
        from mocapkit.io.qmt_mat import read_qmt_mat

        return dict(read_qmt_mat(path).orientation)
    if fmt == "device":
        from mocapkit.io.imu_files import read_device_orientations

        return read_device_orientations(path)
    from mocapkit.io.opensense import read_orientations_sto

    return read_orientations_sto(path)


def load_for_identify(
    path: Path, fmt: str, filter_name: str, mode: str | None
) -> tuple[dict[str, OrientationSeries], Mapping[str, Any] | None, str, str]:
    """What ``body identify`` works on: (orientations, raw samples with ``acc`` or None,
    headings "shared"/"independent", what was used). Raw samples go through
    ``filter_name`` (9D with a magnetometer, else 6D) unless it is ``"device"``."""
    _exists(path)
    fmt = recording_format(path, fmt)
    if fmt == "opensense-sto":
        from mocapkit.io.opensense import read_orientations_sto

        return read_orientations_sto(path), None, "shared", "the file's orientations"
    if fmt == "device" and _is_xsens_without_gyro(path):
        from mocapkit.io.imu_files import read_xsens_directory

        ex = read_xsens_directory(path)
        oris = {k: e.orientation for k, e in ex.items()}
        return oris, ex, "shared", "the devices' orientations and accelerometers"
    recs = read_raw(path, fmt)
    if filter_name == DEVICE:
        from mocapkit.body.identify import align_sensor_frames

        device = load_orientations(path, fmt)
        aligned = {k: align_sensor_frames(device[k], recs[k], k) for k in device if k in recs}
        return device, aligned, "shared", "the devices' orientations and accelerometers"
    has_mag = all(r.has_mag for r in recs.values())
    mode = mode or ("9d" if has_mag else "6d")
    if mode == "9d" and not has_mag:
        raise ConfigError(
            f"{path}: --mode 9d needs magnetometer samples, and some sensors have none; "
            "use --mode 6d"
        )
    oris = run_filter(recs, filter_name, mode)
    headings = "shared" if mode == "9d" else "independent"
    return oris, recs, headings, f"{filter_name} {mode} on the raw samples"


def _is_xsens_without_gyro(path: Path) -> bool:
    from mocapkit.io.imu_files import _is_xsens_dir, read_xsens_directory

    if not (path.is_dir() and _is_xsens_dir(path)):
        return False
    return any(e.gyr is None for e in read_xsens_directory(path).values())
