"""Reader for BROAD trials (Laidig et al., "BROAD - A Benchmark for Robust Inertial
Orientation Estimation", Data 2021), HDF5 files from ``data_hdf5/``.

Each file holds ``imu_gyr`` [rad/s], ``imu_acc`` [m/s^2], ``imu_mag`` [uT], the optical
reference ``opt_quat`` [w, x, y, z] (already in the IMU's ENU frame, NaN where the
cameras lost the body), ``opt_pos`` [m], the boolean ``movement`` mask and the
attribute ``sampling_rate`` [Hz].
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.errors import FileFormatError
from mocapkit.series import ImuRecording, OrientationSeries

_REQUIRED = ("imu_gyr", "imu_acc", "imu_mag", "opt_quat", "movement")


@dataclass(frozen=True)
class BroadTrial:
    """One BROAD trial: IMU samples, optical reference orientation and movement mask."""

    name: str
    imu: ImuRecording
    reference: OrientationSeries
    movement: np.ndarray  # (N,) bool: samples that count for the error metric
    position: np.ndarray  # (N, 3) optical position [m]

    @property
    def rate_hz(self) -> float:
        return float(self.imu.meta["sampling_rate"])


def _read_mat(p: Path) -> dict[str, np.ndarray]:
    """The arrays of a BROAD ``data_mat`` trial (MATLAB 5 file, same names as the HDF5)."""
    import scipy.io

    try:
        data = scipy.io.loadmat(p)
    except (OSError, ValueError, NotImplementedError, scipy.io.matlab.MatReadError) as exc:
        raise FileFormatError(f"{p}: not a readable MATLAB .mat file ({exc})") from exc
    missing = [k for k in (*_REQUIRED, "sampling_rate") if k not in data]
    if missing:
        raise FileFormatError(
            f"{p}: missing variable(s) {', '.join(missing)}; is this a BROAD data_mat trial?"
        )
    return data


def read_broad_trial(path: str | Path) -> BroadTrial:
    """Read one BROAD trial: ``.hdf5`` (``data_hdf5/``) or ``.mat`` (``data_mat/``)."""
    p = Path(path)
    if p.suffix.lower() == ".mat":
        d = _read_mat(p)
        return _trial(
            p,
            float(np.asarray(d["sampling_rate"]).reshape(-1)[0]),
            np.asarray(d["imu_gyr"], dtype=np.float64),
            np.asarray(d["imu_acc"], dtype=np.float64),
            np.asarray(d["imu_mag"], dtype=np.float64),
            np.asarray(d["opt_quat"], dtype=np.float64),
            np.asarray(d["movement"]).astype(bool).reshape(-1),
            np.asarray(d["opt_pos"], dtype=np.float64) if "opt_pos" in d else None,
        )
    f, rate = _open_hdf5(p)
    with f:
        gyr = np.asarray(f["imu_gyr"], dtype=np.float64)
        acc = np.asarray(f["imu_acc"], dtype=np.float64)
        mag = np.asarray(f["imu_mag"], dtype=np.float64)
        quat = np.asarray(f["opt_quat"], dtype=np.float64)
        movement = np.asarray(f["movement"], dtype=bool).reshape(-1)
        pos = np.asarray(f["opt_pos"], dtype=np.float64) if "opt_pos" in f else None
    return _trial(p, rate, gyr, acc, mag, quat, movement, pos)


def _open_hdf5(p: Path) -> tuple[Any, float]:
    """The open h5py file of a BROAD trial, checked, and its sampling rate [Hz]."""
    import h5py

    try:
        f = h5py.File(p, "r")
    except OSError as exc:
        raise FileFormatError(f"{p}: not a readable HDF5 file ({exc})") from exc
    missing = [k for k in _REQUIRED if k not in f]
    if missing or "sampling_rate" not in f.attrs:
        f.close()
        if missing:
            raise FileFormatError(
                f"{p}: missing dataset(s) {', '.join(missing)}; is this a BROAD data_hdf5 trial?"
            )
        raise FileFormatError(f"{p}: missing attribute 'sampling_rate'")
    return f, float(f.attrs["sampling_rate"])


def iter_broad_imu(path: str | Path, chunk_rows: int = 100_000) -> Iterator[ImuRecording]:
    """The IMU samples of a BROAD ``.hdf5`` trial in pieces of ``chunk_rows`` rows, read
    from the file as they go (h5py reads the rows asked for): the recording of
    :func:`read_broad_trial` in bounded memory (``imu run`` on an hour at 1 kHz)."""
    p = Path(path)
    f, rate = _open_hdf5(p)
    with f:
        gyr, acc, mag = f["imu_gyr"], f["imu_acc"], f["imu_mag"]
        n = int(gyr.shape[0])
        if acc.shape[0] != n or mag.shape[0] != n:
            raise FileFormatError(
                f"{p}: imu_gyr has {n} rows, imu_acc {acc.shape[0]}, imu_mag {mag.shape[0]}; "
                "a BROAD trial has one row per sample in each"
            )
        meta = {"sampling_rate": rate, "source": str(p)}
        for a in range(0, n, chunk_rows):
            b = min(n, a + chunk_rows)
            yield ImuRecording(
                np.arange(a, b) / rate,
                np.asarray(gyr[a:b], dtype=np.float64),
                np.asarray(acc[a:b], dtype=np.float64),
                np.asarray(mag[a:b], dtype=np.float64),
                name=p.stem,
                meta=dict(meta),
            )


def _trial(
    p: Path,
    rate: float,
    gyr: np.ndarray,
    acc: np.ndarray,
    mag: np.ndarray,
    quat: np.ndarray,
    movement: np.ndarray,
    pos: np.ndarray | None,
) -> BroadTrial:
    if pos is None:
        pos = np.full((len(gyr), 3), np.nan)
    name = p.stem
    time = np.arange(len(gyr)) / rate
    imu = ImuRecording(
        time, gyr, acc, mag, name=name, meta={"sampling_rate": rate, "source": str(p)}
    )
    ref = OrientationSeries(time, quat, name=f"{name}.reference")
    movement.setflags(write=False)
    pos.setflags(write=False)
    return BroadTrial(name=name, imu=imu, reference=ref, movement=movement, position=pos)


def list_broad_trials(directory: str | Path) -> list[Path]:
    """The ``*.hdf5`` and ``*.mat`` trials in a directory, sorted by name (a trial in both
    formats is listed once, as ``.hdf5``)."""
    d = Path(directory)
    if not d.is_dir():
        raise FileFormatError(f"{d}: not a directory of BROAD .hdf5 or .mat trials")
    hdf5 = {f.stem: f for f in d.glob("*.hdf5")}
    mat = {f.stem: f for f in d.glob("*.mat") if f.stem not in hdf5}
    files = sorted([*hdf5.values(), *mat.values()], key=lambda f: f.name)
    if not files:
        raise FileFormatError(
            f"{d}: no .hdf5 or .mat files found (expected BROAD's data_hdf5 or data_mat trials)"
        )
    return files


def read_broad_crop(path: str | Path) -> BroadTrial:
    """Read a cropped BROAD trial stored as ``.npz`` (same arrays as the HDF5 file, plus
    ``source_trial`` and ``source_start``), e.g. the bundled demo recording."""
    p = Path(path)
    try:
        data = np.load(p, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise FileFormatError(f"{p}: not a readable .npz file ({exc})") from exc
    with data:
        missing = [k for k in (*_REQUIRED, "sampling_rate") if k not in data.files]
        if missing:
            raise FileFormatError(f"{p}: missing array(s) {', '.join(missing)}")
        rate = float(data["sampling_rate"])
        name = p.stem
        start = int(data["source_start"]) if "source_start" in data.files else 0
        gyr, acc, mag = (np.asarray(data[k], dtype=np.float64) for k in _REQUIRED[:3])
        quat = np.asarray(data["opt_quat"], dtype=np.float64)
        movement = np.asarray(data["movement"], dtype=bool).reshape(-1)
    time = (start + np.arange(len(gyr))) / rate
    meta = {"sampling_rate": rate, "source": str(p), "source_start": start}
    imu = ImuRecording(time, gyr, acc, mag, name=name, meta=meta)
    ref = OrientationSeries(time, quat, name=f"{name}.reference")
    movement.setflags(write=False)
    pos = np.full((len(gyr), 3), np.nan)
    pos.setflags(write=False)
    return BroadTrial(name=name, imu=imu, reference=ref, movement=movement, position=pos)


def bundled_demo_trial() -> BroadTrial:
    """The 30 s BROAD crop shipped with mocapkit (``mocapkit/data/broad``, CC BY 4.0)."""
    from importlib.resources import as_file, files

    resource = files("mocapkit") / "data" / "broad" / "07_undisturbed_fast_rotation_B_crop.npz"
    with as_file(resource) as path:
        return read_broad_crop(path)
