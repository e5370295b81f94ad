"""LSL over loopback with the real liblsl (bundled by pylsl): mocapkit's outlets read by
an inlet, an LSL IMU stream recorded into mocapkit, and what bad streams get."""

from __future__ import annotations

import threading
import time
import uuid

import numpy as np
import pytest

pylsl = pytest.importorskip("pylsl", reason="LSL needs pylsl (pip install 'mocapkit[lsl]')")

from mocapkit.errors import ConfigError, DataError  # noqa: E402
from mocapkit.io.lsl import SessionOutlets, record_imu  # noqa: E402

# real sockets against the clock (and one fixed stream name): run serially (see Makefile)
pytestmark = pytest.mark.realtime


def _imu_outlet(name: str, channels: int, n: int, rate: float = 200.0) -> threading.Thread:
    """A thread that opens an outlet and pushes ``n`` samples: gyro (0.1 k, 0, 0.2),
    acc (0, 0, 9.81), mag (20, 0, -40) when 9 channels."""
    info = pylsl.StreamInfo(name, "IMU", channels, rate, "float32", name)
    outlet = pylsl.StreamOutlet(info)

    def run() -> None:
        deadline = time.monotonic() + 5.0
        while not outlet.have_consumers() and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(0.2)
        t0 = pylsl.local_clock()
        for k in range(n):
            row = [0.001 * k, 0.0, 0.2, 0.0, 0.0, 9.81] + (
                [20.0, 0.0, -40.0] if channels == 9 else []
            )
            outlet.push_sample(row, t0 + k / rate)
            time.sleep(1.0 / rate)
        time.sleep(3.0)  # keep the outlet alive while the inlet drains

    th = threading.Thread(target=run, daemon=True)
    th.start()
    return th


def test_an_lsl_imu_stream_is_recorded_with_its_own_clock() -> None:
    name = f"mk-imu-{uuid.uuid4().hex[:6]}"
    _imu_outlet(name, 9, 200)
    rec = record_imu(name, 2.0)
    assert 150 <= rec.n_samples <= 200
    assert rec.has_mag
    np.testing.assert_allclose(rec.acc[:, 2], 9.81, rtol=1e-6)
    np.testing.assert_allclose(rec.mag[0], [20.0, 0.0, -40.0])
    assert rec.rate_hz == pytest.approx(200.0, rel=0.02)  # the outlet's stamps, not arrival
    steps = np.diff(rec.gyr[:, 0]) / 0.001
    assert np.all(steps >= 0.999)  # in order, no sample twice


def test_missing_and_wrong_streams_are_named() -> None:
    with pytest.raises(ConfigError, match="no stream named 'mk-nobody'"):
        record_imu("mk-nobody", 1.0, resolve_timeout_s=0.3)
    name = f"mk-four-{uuid.uuid4().hex[:6]}"
    info = pylsl.StreamInfo(name, "EEG", 4, 100, "float32", name)
    _outlet = pylsl.StreamOutlet(info)
    with pytest.raises(DataError, match="4 channels"):
        record_imu(name, 1.0, resolve_timeout_s=2.0)
    del _outlet


def test_session_outlets_reach_an_inlet_with_their_labels() -> None:
    outlets = SessionOutlets(("hip_flexion_r", "knee_angle_r"), ("pelvis", "thigh"), 100.0)
    found = pylsl.resolve_byprop("name", "mocapkit-joint-angles", timeout=5)
    inlet = pylsl.StreamInlet(found[0])
    inlet.open_stream(timeout=5)
    info = inlet.info()
    ch = info.desc().child("channels").child("channel")
    labels = []
    while not ch.empty():
        labels.append(ch.child_value("label"))
        ch = ch.next_sibling()
    assert labels == ["hip_flexion_r", "knee_angle_r"]
    time.sleep(0.3)
    q = np.tile([1.0, 0.0, 0.0, 0.0], (2, 1))
    for k in range(20):
        outlets.push(np.array([0.1 * k, 0.5]), q)
        time.sleep(0.005)
    time.sleep(0.3)
    chunk, _ = inlet.pull_chunk(timeout=1.0)
    assert len(chunk) == 20
    np.testing.assert_allclose(np.array(chunk)[:, 1], 0.5)
    assert outlets.orientations.get_info().channel_count() == 8


def test_cli_record_lsl_writes_a_mocapkit_csv(tmp_path, capsys) -> None:
    import json

    from mocapkit.cli.main import main
    from mocapkit.io.imu_csv import read_imu_csv

    name = f"mk-cli-{uuid.uuid4().hex[:6]}"
    _imu_outlet(name, 6, 150)
    out = tmp_path / "imu.csv"
    assert main(["imu", "record-lsl", "--stream", name, "--seconds", "1.5", "-o", str(out),
                 "--json"]) == 0  # fmt: skip
    report = json.loads(capsys.readouterr().out)
    assert report["magnetometer"] is False
    rec = read_imu_csv(out)
    assert rec.n_samples == report["samples"] > 100
