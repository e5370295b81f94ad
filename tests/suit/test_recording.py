"""MCAP recording of a live UDP session, bit-for-bit replay, batch decoding, file replay."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import FileFormatError
from mocapkit.suit.receiver import Receiver
from mocapkit.suit.recording import (
    PACKETS_TOPIC,
    SAMPLE_SCHEMA,
    McapRecorder,
    ReplayTransport,
    decode_recording,
    read_frames,
    read_samples,
    replay,
)
from mocapkit.suit.simulator import SuitSimConfig, SuitSimulator
from mocapkit.suit.transport import UdpTransport


def _record(path: Path, send_all: object, samples: str = "at_close") -> tuple[Receiver, int]:
    rx_t = UdpTransport.bind("127.0.0.1", 0)
    rec = McapRecorder(path, samples=samples)  # type: ignore[arg-type]
    rx = Receiver(rx_t, recorder=rec).start()
    tx = UdpTransport.connect("127.0.0.1", rx_t.port)
    try:
        n = send_all(tx.send)  # type: ignore[operator]
        deadline = time.monotonic() + 5.0
        while rec.frames < n and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        rx.stop()
        tx.close()
        rx_t.close()
        rec.close()
    return rx, n


def test_record_then_replay_is_bit_for_bit(tmp_path: Path) -> None:
    sim = SuitSimulator.from_motion(
        "walk", 4, 0.3, 100.0, SuitSimConfig(mode="raw"), np.random.default_rng(0)
    )
    timeline = sim.timeline()
    sent = [f for _, f in timeline]
    bad = [b"\xa5\x01", sent[0][:-1] + b"\x00"]  # record malformed datagrams too

    def first(send):  # type: ignore[no-untyped-def]
        for f in bad:
            send(f)
        return len(bad) + sim.stream(send, speed=0)

    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    rx_a, n = _record(a, first)
    frames_a = [f.data for f in read_frames(a)]
    assert frames_a == bad + sent
    _, n2 = _record(b, lambda send: replay(a, send, speed=0), samples="live")
    assert n2 == n
    assert [f.data for f in read_frames(b)] == frames_a
    assert rx_a.stats().dropped == {"truncated": 1, "bad_crc": 1}
    samples = read_samples(a)  # decoded at close
    live = read_samples(b)  # the receiver's delivered samples
    assert len(samples) == len(live) == len(sent)
    assert set(samples[0]) == set(SAMPLE_SCHEMA["properties"])  # type: ignore[arg-type]
    assert samples[0]["kind"] == "RAW"
    assert len(samples[0]["gyr"]) == 3
    by_key = {(m["sensor_id"], m["seq"]): m for m in live}
    assert sorted(by_key) == sorted((m["sensor_id"], m["seq"]) for m in samples)
    for m in samples:
        assert m["gyr"] == by_key[(m["sensor_id"], m["seq"])]["gyr"]
    dec = decode_recording(a)
    assert len(dec) == len(sent)
    assert dec.n_frames == len(sent)
    np.testing.assert_array_equal(np.sort(np.unique(dec.sensor_id)), [1, 2, 3, 4])


def test_mcap_layout_opens_as_foxglove_expects(tmp_path: Path) -> None:
    from mcap.reader import make_reader

    path = tmp_path / "r.mcap"
    with McapRecorder(path) as rec:
        rec.write_frame(b"\xa5abc", time.perf_counter_ns(), ("127.0.0.1", 5))
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    topics = {c.topic: c for c in summary.channels.values()}
    assert topics[PACKETS_TOPIC].metadata == {"source": "('127.0.0.1', 5)"}
    schema = summary.schemas[topics["/suit/samples"].schema_id]
    assert schema.encoding == "jsonschema"
    assert topics["/suit/samples"].message_encoding == "json"
    assert json.loads(schema.data)["title"] == "mocapkit.suit.Sample"


def test_replay_transport_feeds_a_receiver(tmp_path: Path) -> None:
    sim = SuitSimulator.from_motion(
        "static", 2, 0.2, 50.0, SuitSimConfig(), np.random.default_rng(1)
    )
    path = tmp_path / "s.mcap"
    _, n = _record(path, lambda send: sim.stream(send, speed=0))
    t = ReplayTransport(path, speed=0)
    rx = Receiver(t).start()
    got = []
    deadline = time.monotonic() + 5.0
    while len(got) < n and time.monotonic() < deadline:
        got += rx.get_batch(100, 0.05)
    rx.stop()
    assert len(got) == n
    assert t.finished


def test_replay_paces_at_the_requested_speed(tmp_path: Path) -> None:
    path = tmp_path / "p.mcap"
    t0 = time.perf_counter_ns()
    with McapRecorder(path) as rec:
        for i in range(3):
            rec.write_frame(bytes([i]), t0 + i * 100_000_000, "x")
    times: list[float] = []
    stop = threading.Event()
    start = time.perf_counter()
    replay(path, lambda b: times.append(time.perf_counter() - start), speed=2.0, stop=stop)
    # 100 ms spacing at speed 2 -> the last frame at 100 ms, never earlier
    assert times[-1] >= 0.1 - 1e-3


def test_bad_recording_files(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="no such file"):
        read_frames(tmp_path / "missing.mcap")
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"this is not mcap" * 10)
    with pytest.raises(FileFormatError, match="not a readable MCAP recording"):
        read_frames(junk)


def test_fast_frame_reader_equals_the_mcap_reader(tmp_path: Path) -> None:
    from mocapkit.suit.mcap_fast import read_frame_buffer

    path = tmp_path / "f.mcap"
    t0 = time.perf_counter_ns()
    rng = np.random.default_rng(0)
    frames = [
        bytes(rng.integers(0, 256, int(rng.integers(1, 60)), dtype=np.uint8)) for _ in range(3000)
    ]
    with McapRecorder(path) as rec:
        for i, f in enumerate(frames):
            # two sources (two channels); equal times keep their arrival order
            rec.write_frame(f, t0 + (i // 3) * 1000, ("a", i % 2))
    ref = read_frames(path)
    fb = read_frame_buffer(path)
    assert len(fb) == len(ref) == len(frames)
    assert [fb.frame(i) for i in range(len(fb))] == [r.data for r in ref] == frames
    np.testing.assert_array_equal(fb.log_time_ns, [r.log_time_ns for r in ref])
    with pytest.raises(FileNotFoundError):
        read_frame_buffer(tmp_path / "nope.mcap")


def test_sample_json_is_valid_and_complete() -> None:
    from mocapkit.suit.protocol import Kind
    from mocapkit.suit.recording import sample_json
    from mocapkit.suit.samples import SuitSample

    raw = SuitSample(3, 7, 1.25, 99, Kind.RAW, None, np.array([0.1, -2.0, 3e-7]),
                     np.array([0.0, 0.0, 9.81]), None)  # fmt: skip
    ori = SuitSample(1, 2, float("nan"), 5, Kind.ORIENTATION, np.array([1.0, 0.0, 0.0, 0.0]),
                     source="slimevr")  # fmt: skip
    a, b = json.loads(sample_json(raw)), json.loads(sample_json(ori))
    assert set(a) == set(b) == set(SAMPLE_SCHEMA["properties"])  # type: ignore[arg-type]
    assert a["gyr"] == [0.1, -2.0, 3e-7]
    assert a["mag"] is None
    assert a["kind"] == "RAW"
    assert b["t_sensor_s"] is None
    assert b["quat"] == {"w": 1.0, "x": 0.0, "y": 0.0, "z": 0.0}
