"""Reader for qmt-style full-body ``.mat`` recordings (``full_body_example_data.mat`` of
github.com/dlaidig/qmt): a time vector ``t`` [s] and one struct per segment with ``acc``
[m/s^2], ``gyr`` [rad/s] and ``quat`` [w, x, y, z], the sensor's own orientation.

Pitfall (measured on the file): ``quat`` is expressed in a sensor frame rotated against
the ``acc``/``gyr`` frame (a fixed rotation per sensor, found by fitting the rate of
``quat`` to ``gyr``), so do not mix the two; the body pipeline works on ``quat`` alone.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mocapkit.errors import FileFormatError
from mocapkit.series import ImuRecording, OrientationSeries


@dataclass(frozen=True)
class QmtRecording:
    """Per segment (the file's names): raw IMU samples and the sensor's own orientation."""

    imu: dict[str, ImuRecording]
    orientation: dict[str, OrientationSeries]
    source: str

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.orientation)


def read_qmt_mat(path: str | Path) -> QmtRecording:
    """Read a qmt ``.mat`` recording (scipy.io.loadmat; MATLAB v5/v7)."""
    import scipy.io

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such file")
    try:
        data = scipy.io.loadmat(p, squeeze_me=False)
    except (ValueError, NotImplementedError, OSError, scipy.io.matlab.MatReadError) as exc:
        raise FileFormatError(f"{p}: not a readable MATLAB .mat file ({exc})") from exc
    if "t" not in data:
        raise FileFormatError(f"{p}: no time vector 't'; is this a qmt full-body recording?")
    time = np.asarray(data["t"], dtype=np.float64).reshape(-1)
    imu: dict[str, ImuRecording] = {}
    ori: dict[str, OrientationSeries] = {}
    for key, value in data.items():
        if key.startswith("__") or key == "t":
            continue
        names = getattr(getattr(value, "dtype", None), "names", None)
        if not names or not {"acc", "gyr", "quat"} <= set(names):
            raise FileFormatError(
                f"{p}: entry {key!r} is not a segment struct with fields acc, gyr, quat "
                f"(fields: {names})"
            )
        rec = value[0, 0]
        fields = {}
        for f, width in (("acc", 3), ("gyr", 3), ("quat", 4)):
            arr = np.asarray(rec[f], dtype=np.float64)
            if arr.shape != (time.shape[0], width):
                raise FileFormatError(
                    f"{p}: {key}.{f} has shape {arr.shape}, expected ({time.shape[0]}, {width})"
                )
            fields[f] = arr
        meta = {"source": str(p)}
        imu[key] = ImuRecording(time, fields["gyr"], fields["acc"], name=key, meta=meta)
        q = fields["quat"]
        q = q / np.linalg.norm(q, axis=1, keepdims=True)
        ori[key] = OrientationSeries(time, q, name=key)
    if not ori:
        raise FileFormatError(f"{p}: no segment structs found")
    return QmtRecording(imu=imu, orientation=ori, source=str(p))
