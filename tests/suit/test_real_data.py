"""A real 15-IMU full-body recording streamed through the suit: nodes -> hub -> UDP ->
receiver, every sample delivered, values within the wire quantisation."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from mocapkit.series import ImuRecording
from mocapkit.suit.bus import Hub, InProcessBus
from mocapkit.suit.node import SensorNode
from mocapkit.suit.protocol import ACC_LSB, GYR_LSB, Kind
from mocapkit.suit.receiver import Receiver
from mocapkit.suit.recording import paced
from mocapkit.suit.transport import UdpTransport

# runs live processes and sockets against the clock: run serially (see Makefile)
pytestmark = pytest.mark.realtime


@pytest.mark.shared_data
def test_full_body_15_imu_recording_over_the_suit(shared_data: Path) -> None:
    import scipy.io

    mat = scipy.io.loadmat(
        shared_data / "full-body-15-imu" / "full_body_example_data.mat", simplify_cells=True
    )
    names = sorted(k for k in mat if not k.startswith("__") and k != "t")
    # the file holds 16 segments (the README says 15); the suit addresses 15 IDs
    assert len(names) >= 15
    names = names[:15]
    n = 300  # 3 s at 100 Hz
    t = np.asarray(mat["t"], dtype=np.float64)[:n]
    bus = InProcessBus()
    recs = {}
    for sid, name in enumerate(names, start=1):
        rec = ImuRecording(t, mat[name]["gyr"][:n], mat[name]["acc"][:n], name=name)
        recs[sid] = rec
        bus.attach(SensorNode(sid, rec, "raw", clock_offset_us=sid * 1_000_003))
    hub = Hub(bus)
    timeline = [(float(tk), f) for tk in t for f in hub.poll_round(float(tk))]
    assert len(timeline) == 15 * n

    rx_t = UdpTransport.bind("127.0.0.1", 0)
    tx = UdpTransport.connect("127.0.0.1", rx_t.port)
    rx = Receiver(rx_t).start()
    got = []
    try:
        paced(timeline, tx.send, speed=0)
        deadline = time.monotonic() + 10.0
        while len(got) < len(timeline) and time.monotonic() < deadline:
            got += rx.get_batch(4096, 0.05)
    finally:
        rx.stop()
        tx.close()
        rx_t.close()
    assert len(got) == len(timeline)
    assert rx.stats().dropped == {}
    for sid, rec in recs.items():
        mine = sorted((s for s in got if s.sensor_id == sid), key=lambda s: s.seq)
        assert [s.seq for s in mine] == list(range(n))
        assert all(s.kind is Kind.RAW and s.mag is None for s in mine)
        gyr = np.array([s.gyr for s in mine])
        acc = np.array([s.acc for s in mine])
        # the wire's int16 quantisation: half an LSB per axis (plus float rounding)
        assert np.abs(gyr - rec.gyr).max() <= GYR_LSB / 2 + 1e-9
        assert np.abs(acc - rec.acc).max() <= ACC_LSB / 2 + 1e-9
        ts = np.array([s.t_sensor_s for s in mine])
        np.testing.assert_allclose(np.diff(ts), np.diff(rec.time), atol=1e-6)  # us clock
