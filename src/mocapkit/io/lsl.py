"""Lab Streaming Layer (LSL, ``pylsl`` with the liblsl it bundles): mocapkit's live data as
LSL outlets, and LSL IMU streams recorded into mocapkit.

Outlets (:class:`SessionOutlets`, ``mocapkit teleop run --lsl``), one sample per processed
suit frame, stamped with ``pylsl.local_clock()`` when the frame was processed:

- ``mocapkit-joint-angles`` (type ``MoCap``): the body model's joint angles [rad], one
  channel per OpenSim coordinate (channel labels in the stream's description);
- ``mocapkit-orientations`` (type ``Orientation``): every sensor's ``q_world_sensor``,
  4 channels per sensor ``<sensor>_qw, _qx, _qy, _qz``;
- ``mocapkit-imu-<sensor>`` (type ``IMU``, :class:`RawOutlets`, with host-side fusion:
  the suit sends raw samples then): every raw sample as it arrives, gyroscope [rad/s],
  accelerometer [m/s^2] and, with magnetometers, the field [uT].

Inlet (:func:`record_imu`, ``mocapkit imu record-lsl``): an LSL stream of IMU samples
(6 channels gyroscope [rad/s] then accelerometer [m/s^2], or 9 with a magnetometer, in
that order) recorded for a while into an :class:`~mocapkit.series.ImuRecording` with the
stream's own timestamps; written as mocapkit's IMU CSV by the command. A stream that
does not appear, has another channel count, or stops is a clear error or a warning
naming it; nothing received is dropped.
"""

from __future__ import annotations

import contextlib
import logging
import time
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError, DataError, MissingDependencyError
from mocapkit.series import ImuRecording

log = logging.getLogger("mocapkit.io.lsl")

QUIET = "[log]\nlevel = -2\n"  # liblsl logs INFO lines to stderr by default


def pylsl() -> Any:
    try:
        import pylsl as lsl
    except (ImportError, RuntimeError, OSError) as exc:  # no pylsl, or no liblsl for it
        raise MissingDependencyError(
            f"LSL needs pylsl and liblsl ({exc}): pip install 'mocapkit[lsl]' (its Linux "
            "wheels bundle liblsl for glibc >= 2.35; elsewhere install liblsl from "
            "github.com/sccn/liblsl releases or conda-forge and set PYLSL_LIB)"
        ) from exc
    with contextlib.suppress(Exception):  # a liblsl configured already keeps its settings
        lsl.set_config_content(QUIET)
    return lsl


def _outlet(lsl: Any, name: str, kind: str, labels: Sequence[str], rate_hz: float) -> Any:
    info = lsl.StreamInfo(name, kind, len(labels), rate_hz, "float32", f"mocapkit-{name}")
    chans = info.desc().append_child("channels")
    for label in labels:
        chans.append_child("channel").append_child_value("label", label)
    return lsl.StreamOutlet(info)


class SessionOutlets:
    """The two outlets of a live session (module docstring); ``push(angles, q_sensor)``
    once per frame (NaN where unknown)."""

    def __init__(
        self, coordinates: Sequence[str], sensors: Sequence[str], rate_hz: float = 100.0
    ) -> None:
        lsl = pylsl()
        self._clock = lsl.local_clock
        self.angles = _outlet(lsl, "mocapkit-joint-angles", "MoCap", coordinates, rate_hz)
        labels = [f"{s}_q{c}" for s in sensors for c in "wxyz"]
        self.orientations = _outlet(lsl, "mocapkit-orientations", "Orientation", labels, rate_hz)
        self.n_angles = len(coordinates)
        self.n_quats = 4 * len(sensors)
        self.pushed = 0

    def push(self, angles: FloatArray | None, q_sensor: FloatArray | None) -> None:
        t = self._clock()
        if angles is not None and len(angles) == self.n_angles:
            self.angles.push_sample(np.asarray(angles, dtype=np.float32).tolist(), t)
        if q_sensor is not None and np.size(q_sensor) == self.n_quats:
            self.orientations.push_sample(
                np.asarray(q_sensor, dtype=np.float32).ravel().tolist(), t
            )
        self.pushed += 1


class RawOutlets:
    """The suit's raw IMU samples, one LSL outlet per sensor (module docstring):
    ``mocapkit-imu-<sensor>``, type ``IMU``, 6 channels (gyroscope [rad/s], accelerometer
    [m/s^2]) or 9 with ``with_mag`` (and the magnetometer [uT], NaN where a sample has
    none), the layout :func:`record_imu` and other LSL IMU consumers read. Each sample is
    stamped with its sensor's clock, put on LSL's clock at that sensor's first sample (the
    sensor's own spacing, not the network's jitter); a sensor without a clock (NaN) is
    stamped when pushed. ``push(samples)`` takes a batch of ``SuitSample`` (orientation
    samples and unknown sensors are skipped) and returns the samples pushed."""

    def __init__(self, sensors: Mapping[int, str], rate_hz: float, with_mag: bool) -> None:
        lsl = pylsl()
        self._clock = lsl.local_clock
        axes = ("gyr", "acc", "mag") if with_mag else ("gyr", "acc")
        labels = [f"{a}_{c}" for a in axes for c in "xyz"]
        self.outlets = {sid: _outlet(lsl, f"mocapkit-imu-{name}", "IMU", labels, rate_hz)
                        for sid, name in sensors.items()}  # fmt: skip
        self.with_mag = with_mag
        self._offset: dict[int, float] = {}
        self._nan3 = [float("nan")] * 3
        self.pushed = 0

    def push(self, samples: Sequence[Any]) -> int:
        n = 0
        for s in samples:
            outlet = self.outlets.get(s.sensor_id)
            if outlet is None or s.gyr is None or s.acc is None:
                continue
            row = [*s.gyr, *s.acc]
            if self.with_mag:
                row += list(s.mag) if s.mag is not None else self._nan3
            t_s = s.t_sensor_s
            if t_s == t_s:  # the sensor's clock, anchored to LSL's at its first sample
                off = self._offset.get(s.sensor_id)
                if off is None:
                    off = self._offset[s.sensor_id] = self._clock() - t_s
                outlet.push_sample(row, t_s + off)
            else:
                outlet.push_sample(row, self._clock())
            n += 1
        self.pushed += n
        return n


def record_imu(name: str, seconds: float, *, resolve_timeout_s: float = 5.0) -> ImuRecording:
    """Record the LSL stream ``name`` (IMU samples, module docstring) for ``seconds``."""
    lsl = pylsl()
    found = lsl.resolve_byprop("name", name, timeout=resolve_timeout_s)
    if not found:
        raise ConfigError(
            f"LSL: no stream named {name!r} within {resolve_timeout_s:g} s (is its outlet "
            "running, on this network?)"
        )
    info = found[0]
    n = info.channel_count()
    if n not in (6, 9):
        raise DataError(
            f"LSL stream {name!r}: {n} channels; an IMU stream has 6 (gyroscope rad/s, "
            "accelerometer m/s^2) or 9 (and a magnetometer)"
        )
    inlet = lsl.StreamInlet(info, max_buflen=max(1, int(np.ceil(seconds)) + 5))
    inlet.open_stream(timeout=resolve_timeout_s)
    rows: list[list[float]] = []
    stamps: list[float] = []
    end = time.monotonic() + seconds
    last_data = time.monotonic()
    while time.monotonic() < end:
        chunk, ts = inlet.pull_chunk(timeout=0.1)
        if chunk:
            rows.extend(chunk)
            stamps.extend(ts)
            last_data = time.monotonic()
        elif time.monotonic() - last_data > 2.0 and rows:
            warnings.warn(
                f"LSL stream {name!r} stopped sending after {len(rows)} samples; recording "
                "what arrived",
                stacklevel=2,
            )
            break
    inlet.close_stream()
    if len(rows) < 2:
        raise DataError(f"LSL stream {name!r}: {len(rows)} sample(s) in {seconds:g} s")
    data = np.asarray(rows, dtype=float)
    t = np.asarray(stamps, dtype=float)
    order = np.argsort(t, kind="stable")
    data, t = data[order], t[order] - t[order][0]
    keep = np.concatenate([[True], np.diff(t) > 0])  # repeated stamps: the first kept
    data, t = data[keep], t[keep]
    mag = data[:, 6:9] if n == 9 else None
    return ImuRecording(t, data[:, :3], data[:, 3:6], mag, name=name)
