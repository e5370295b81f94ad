"""Nodes, the pluggable bus, and the hub's polling semantics (paper section 4); motions."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_rotate
from mocapkit.imu.filters import available_filters, make_filter
from mocapkit.imu.simulate import simulate_imu
from mocapkit.suit.bus import Bus, Hub, InProcessBus
from mocapkit.suit.motions import FULL_BODY_SEGMENTS, body_motion, mount, suit_poses
from mocapkit.suit.node import SensorNode
from mocapkit.suit.protocol import Kind, decode, encode_orientation
from mocapkit.suit.simulator import SuitSimConfig, SuitSimulator


def _node(sid: int, n: int = 21, **kw: object) -> SensorNode:
    rec = simulate_imu(suit_poses("wave", 1, (n - 1) / 100.0, 100.0)[1])
    return SensorNode(sid, rec, **kw)  # type: ignore[arg-type]


def test_hub_polls_every_id_and_retries_silent_ones() -> None:
    bus = InProcessBus()
    bus.attach(_node(2))
    bus.attach(_node(5))
    hub = Hub(bus)
    frames = hub.poll_round(0.0)
    # 2 answering IDs once, 13 silent IDs three times each (1 + 2 retries)
    assert (hub.stats.polls, hub.stats.silent, hub.stats.retries) == (2 + 13 * 3, 13, 13 * 2)
    assert sorted(decode(f).sensor_id for f in frames) == [2, 5]


def test_busy_nodes_are_retried() -> None:
    bus = InProcessBus(busy_probability=0.5, rng=np.random.default_rng(0))
    bus.attach(_node(1, n=2001))
    hub = Hub(bus, max_id=1)
    for k in range(2000):
        hub.poll_round(k / 100.0)
    # silent after 3 tries with probability 1/8: 250 expected, sd ~ 15
    assert abs(hub.stats.silent - 250) < 75
    assert hub.stats.retries > 0


class _CorruptingBus(InProcessBus):
    """A bus with a noisy line: flips one bit in every answer of sensor 3."""

    def request(self, sensor_id: int, t: float) -> list[bytes] | None:
        out = super().request(sensor_id, t)
        if out and sensor_id == 3:
            out = [p[:12] + bytes([p[12] ^ 0x10]) + p[13:] for p in out]
        return out


def test_hub_drops_invalid_packets(caplog: pytest.LogCaptureFixture) -> None:
    bus = _CorruptingBus()
    bus.attach(_node(1))
    bus.attach(_node(3))
    hub = Hub(bus)
    frames = hub.poll_round(0.0)
    assert [decode(f).sensor_id for f in frames] == [1]
    assert hub.stats.invalid == 1
    assert "dropped an invalid packet from sensor 3" in caplog.text


class _OrientationBus(Bus):
    """Sensors that each answer one ORIENTATION packet per poll (a fixed pose per ID)."""

    def __init__(self, ids: list[int]) -> None:
        self.ids = ids
        self.seq = 0

    def request(self, sensor_id: int, t: float) -> list[bytes] | None:
        if sensor_id not in self.ids:
            return None
        q = np.array([1.0, 0.1 * sensor_id, 0.0, 0.0])
        self.seq += 1
        return [encode_orientation(sensor_id, self.seq, int(t * 1e6), q / np.linalg.norm(q))]


def test_hub_bundles_a_round_of_orientations() -> None:
    hub = Hub(_OrientationBus([1, 3, 7]), clock_offset_us=500)
    frames = hub.poll_round(0.25)
    assert len(frames) == 1
    b = decode(frames[0])
    assert b.kind is Kind.BUNDLE
    assert b.seq == 0
    assert b.t_us == 250_500
    assert [sid for sid, _ in b.entries] == [1, 3, 7]
    for sid, q in b.entries:
        ref = np.array([1.0, 0.1 * sid, 0, 0]) / np.linalg.norm([1.0, 0.1 * sid])
        assert abs(abs(float(np.dot(q, ref))) - 1.0) < 1e-8  # 15-bit quantisation
    assert decode(hub.poll_round(0.26)[0]).seq == 1
    assert len(frames[0]) == 12 + 7 * 3


def test_raw_node_forwards_every_sample_in_order() -> None:
    node = _node(4, n=101, max_raw_per_poll=8)
    seqs = []
    for k in range(200):
        seqs += [decode(p).seq for p in node.answer(k / 100.0)]
    assert seqs == list(range(101))
    assert node.finished


def test_node_and_bus_validation() -> None:
    rec = simulate_imu(suit_poses("static", 1, 0.1, 100.0)[1])
    with pytest.raises(ConfigError, match="sensor_id: expected 1..15, got 16"):
        SensorNode(16, rec)
    with pytest.raises(ConfigError, match="mode: expected 'orientation' or 'raw'"):
        SensorNode(1, rec, mode="quat")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="on-node fusion needs a filter"):
        SensorNode(1, rec, mode="orientation")
    bus = InProcessBus()
    bus.attach(SensorNode(1, rec))
    with pytest.raises(ConfigError, match="sensor_id 1: already on the bus"):
        bus.attach(SensorNode(1, rec))
    with pytest.raises(ConfigError, match="busy_probability"):
        InProcessBus(busy_probability=1.0)
    with pytest.raises(ConfigError, match="tries: expected >= 1"):
        Hub(bus, tries=0)


def test_motions_and_mounting() -> None:
    seg = body_motion("walk", 2.0, 50.0)
    assert set(seg) == set(FULL_BODY_SEGMENTS)
    pelvis = seg["pelvis"]
    assert pelvis.pos[-1, 1] - pelvis.pos[0, 1] == pytest.approx(2.4)  # 1.2 m/s forward
    q_ss = np.array([np.cos(0.3), 0.0, np.sin(0.3), 0.0])
    s = mount(seg["forearm_r"], q_ss, (0.0, 0.05, -0.1))
    np.testing.assert_allclose(
        s.pos, seg["forearm_r"].pos + quat_rotate(seg["forearm_r"].quat, [0.0, 0.05, -0.1])
    )
    with pytest.raises(ConfigError, match="motion: unknown 'jump'"):
        body_motion("jump", 1.0, 100.0)
    with pytest.raises(ConfigError, match="n_sensors: expected 1..15, got 16"):
        suit_poses("walk", 16, 1.0, 100.0)


def test_raw_simulator_timeline() -> None:
    sim = SuitSimulator.from_motion(
        "walk", 15, 0.5, 200.0, SuitSimConfig(), np.random.default_rng(0)
    )
    frames = [f for _, f in sim.timeline()]
    assert len(frames) == 15 * 101
    assert sim.timeline() is sim.timeline()


@pytest.mark.parametrize("name", available_filters() or ["<none registered>"])
def test_on_node_fusion_sends_what_the_node_filter_computes(name: str) -> None:
    if name == "<none registered>":
        pytest.skip("no orientation filter registered yet (the imu part lands them)")
    poses = suit_poses("wave", 3, 2.0, 100.0)
    cfg = SuitSimConfig(mode="orientation", filter_name=name)
    sim = SuitSimulator(poses, cfg, np.random.default_rng(0))
    bundles = [decode(f) for _, f in sim.timeline()]
    assert all(b.kind is Kind.BUNDLE for b in bundles)
    assert len(bundles) == sim.recordings[1].n_samples  # one hub round per sample
    for sid in (1, 2, 3):
        rec = sim.recordings[sid]
        # the node runs its filter sample by sample as the hub polls it
        f = make_filter(name, 100.0)
        ref = np.array(
            [f.update(g, a, m) for g, a, m in zip(rec.gyr, rec.acc, rec.mag, strict=True)]
        )
        sent = np.array([dict(b.entries)[sid] for b in bundles])
        dots = np.abs(np.sum(sent * ref, axis=1))
        # only the wire's smallest-three quantisation separates them (<= 1.5e-4 rad)
        assert np.all(2 * np.arccos(np.minimum(1.0, dots)) < 1.6e-4)
    # the pelvis stands still in "wave": its node converges onto the truth (9D)
    truth = poses[1].quat[-1]
    last = dict(bundles[-1].entries)[1]
    assert np.rad2deg(2 * np.arccos(min(1.0, abs(float(np.dot(last, truth)))))) < 2.0


@pytest.mark.parametrize("name", available_filters() or ["<none registered>"])
def test_host_fusion_runs_the_filter_on_the_received_samples(name: str) -> None:
    if name == "<none registered>":
        pytest.skip("no orientation filter registered yet (the imu part lands them)")
    from mocapkit.suit.fusion import HostFusion
    from mocapkit.suit.receiver import Receiver
    from mocapkit.suit.transport import Frame, UdpTransport

    poses = suit_poses("wave", 2, 1.0, 100.0)
    sim = SuitSimulator(poses, SuitSimConfig(mode="raw"), np.random.default_rng(0))
    t = UdpTransport.bind("127.0.0.1", 0)
    rx = Receiver(t)
    for _, f in sim.timeline():
        rx.handle(Frame(f, "sim", 0))
    t.close()
    samples = rx.get_batch(10_000, 0.0)
    batch = HostFusion(name, 100.0).process_batch(samples)
    single = [HostFusion(name, 100.0).process(s) for s in samples[:1]]
    assert single[0].kind is Kind.ORIENTATION
    for sid in (1, 2):
        mine = [s for s in samples if s.sensor_id == sid]
        ref = make_filter(name, 100.0).run(
            np.array([s.gyr for s in mine]),
            np.array([s.acc for s in mine]),
            np.array([s.mag for s in mine]),
        )
        out = np.array([s.quat for s in batch if s.sensor_id == sid])
        np.testing.assert_allclose(out, ref, atol=1e-12)  # the same filter on the same input
