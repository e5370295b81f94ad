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


def test_raw_suit_samples_reach_an_lsl_imu_recording() -> None:
    """RawOutlets (one outlet per sensor) read back by mocapkit's own LSL IMU recorder:
    the values, the sensor's sample spacing as the stamps, a magnetometer gap as a gap."""
    from mocapkit.io.lsl import RawOutlets
    from mocapkit.suit.samples import Kind, SuitSample

    tag = uuid.uuid4().hex[:6]
    raw = RawOutlets({3: f"thigh{tag}", 4: f"shank{tag}"}, 100.0, with_mag=True)
    got: dict[str, object] = {}

    def record() -> None:
        got["rec"] = record_imu(f"mocapkit-imu-thigh{tag}", 2.0)

    th = threading.Thread(target=record)
    th.start()
    outlet = raw.outlets[3]
    deadline = time.monotonic() + 5.0
    while not outlet.have_consumers() and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(0.2)
    pushed = 0
    for k in range(100):
        batch = [
            SuitSample(sid, k, 10.0 + 0.01 * k, time.perf_counter_ns(), Kind.RAW,
                       gyr=np.array([0.01 * k, 0.0, sid]), acc=np.array([0.0, 0.0, 9.81]),
                       mag=None if k == 50 else np.array([20.0, 0.0, -40.0]))
            for sid in (3, 4, 9)  # 9: a sensor without an outlet, skipped
        ]  # fmt: skip
        batch.append(SuitSample(3, k, 10.0, 0, Kind.ORIENTATION, quat=np.array([1.0, 0, 0, 0])))
        pushed += raw.push(batch)
        time.sleep(0.005)
    th.join(10.0)
    assert pushed == 200  # two sensors with outlets, raw samples only
    rec = got["rec"]
    assert rec.n_samples == 100  # type: ignore[attr-defined]
    np.testing.assert_allclose(rec.gyr[:, 0], 0.01 * np.arange(100), atol=1e-6)  # type: ignore[attr-defined]
    np.testing.assert_allclose(rec.gyr[:, 2], 3.0)  # type: ignore[attr-defined]
    np.testing.assert_allclose(np.diff(rec.time), 0.01, atol=1e-6)  # type: ignore[attr-defined]
    assert np.isnan(rec.mag[50]).all()  # type: ignore[attr-defined]
    np.testing.assert_allclose(rec.mag[49], [20.0, 0.0, -40.0])  # type: ignore[attr-defined]


def test_teleop_run_lsl_adds_raw_outlets_with_host_fusion() -> None:
    """``teleop run --lsl`` with host-side fusion: every batch the session takes goes to
    the sensors' raw outlets too (the session's own batch path, no suit needed)."""
    from mocapkit.teleop.live import LiveConfig, LiveSession
    from mocapkit.teleop.pipeline import PipelineConfig

    cfg = LiveConfig(pipeline=PipelineConfig(fusion="host", use_mag=False))
    live = LiveSession(cfg, ("127.0.0.1", 9))  # a robot address nobody answers: not used
    try:
        _check_raw_outlets(live)
    finally:
        live.link.close()


def _check_raw_outlets(live) -> None:  # type: ignore[no-untyped-def]
    from mocapkit.suit.samples import Kind, SuitSample
    from mocapkit.teleop.run import _lsl_outlets

    _lsl_outlets(live)
    assert len(live.batch_listeners) == 1
    sid = dict(live.pipeline.sensor_ids)["upper_arm_r"]
    found = pylsl.resolve_byprop("name", "mocapkit-imu-upper_arm_r", timeout=5)
    inlet = pylsl.StreamInlet(found[0])
    inlet.open_stream(timeout=5)
    assert inlet.info().channel_count() == 6  # no magnetometer in this session
    time.sleep(0.3)
    for k in range(30):
        s = SuitSample(sid, k, 0.01 * k, time.perf_counter_ns(), Kind.RAW,
                       gyr=np.array([0.1, 0.0, 0.0]), acc=np.array([0.0, 0.0, 9.81]))  # fmt: skip
        live._on_batch([s], time.perf_counter_ns())
    time.sleep(0.3)
    chunk, stamps = inlet.pull_chunk(timeout=1.0)
    assert len(chunk) == 30
    np.testing.assert_allclose(np.array(chunk)[:, 5], 9.81, rtol=1e-6)
    np.testing.assert_allclose(np.diff(stamps), 0.01, atol=1e-6)
