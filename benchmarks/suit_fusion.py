"""Benchmark: orientation accuracy through the suit, on-node fusion (the paper's design,
over its 33.6 kbit/s radio) against host-side fusion (raw samples), per filter.

A simulated 15-sensor suit (``--motion``, 100 Hz, consumer-grade IMU errors) runs
through nodes, hub and wire encoding; every received orientation is compared with the
true ``q_world_sensor`` at the sample it describes. On-node: the hub polls at 95 % of the
radio's rate (27 Hz for 15 sensors) and sends the latest orientation of each node.
Host-side: every raw sample (int16 on the wire) goes to ``HostFusion``.

Run: ``.venv/bin/python -m benchmarks.suit_fusion [--seconds 20] [--motion walk]``.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from mocapkit.imu.filters import available_filters
from mocapkit.imu.simulate import ImuErrorModel
from mocapkit.suit.fusion import HostFusion
from mocapkit.suit.motions import suit_poses
from mocapkit.suit.protocol import Kind, decode
from mocapkit.suit.radio import ours_round_bytes, update_rate_hz
from mocapkit.suit.receiver import Receiver
from mocapkit.suit.simulator import SuitSimConfig, SuitSimulator
from mocapkit.suit.transport import Frame, UdpTransport


def _angle_deg(q: np.ndarray, ref: np.ndarray) -> np.ndarray:
    dots = np.abs(np.sum(q * ref, axis=-1))
    return np.rad2deg(2 * np.arccos(np.minimum(1.0, dots)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--motion", default="walk")
    args = ap.parse_args()
    rate = 100.0
    n = 15
    poses = suit_poses(args.motion, n, args.seconds, rate)
    errors = ImuErrorModel.consumer_grade()
    round_hz = 0.95 * update_rate_hz(ours_round_bytes(n))
    rows = []
    for name in available_filters():
        cfg = SuitSimConfig(mode="orientation", filter_name=name, errors=errors, round_hz=round_hz)
        on_node = SuitSimulator(poses, cfg, np.random.default_rng(1))
        err_node = []
        for t, frame in on_node.timeline():
            k = min(int(np.floor(t * rate + 1e-6)), len(poses[1].time) - 1)
            for sid, q in decode(frame).entries:
                err_node.append(_angle_deg(q, poses[sid].quat[k]))
        raw_cfg = SuitSimConfig(mode="raw", errors=errors)
        host = SuitSimulator(poses, raw_cfg, np.random.default_rng(1))
        transport = UdpTransport.bind("127.0.0.1", 0)
        rx = Receiver(transport)
        for t, frame in host.timeline():  # arrival = send time (no network delay)
            rx.handle(Frame(frame, "sim", int(t * 1e9)))
        assert not rx.stats().dropped, rx.stats().dropped
        transport.close()
        fused = HostFusion(name, rate).process_batch(rx.get_batch(10**7, 0.0))
        err_host = [
            _angle_deg(s.quat, poses[s.sensor_id].quat[s.seq])
            for s in fused
            if s.kind is Kind.ORIENTATION and s.quat is not None
        ]
        skip = int(2.0 * rate)  # leave out the first 2 s (initial convergence)
        node = np.array(err_node[skip * n // 4 :])
        hostv = np.array(err_host)
        rows.append(
            {
                "filter": name,
                "on_node_updates_per_sensor_hz": round_hz,
                "on_node_mean_deg": float(node.mean()),
                "on_node_p95_deg": float(np.percentile(node, 95)),
                "host_updates_per_sensor_hz": rate,
                "host_mean_deg": float(hostv[skip * n :].mean()),
                "host_p95_deg": float(np.percentile(hostv[skip * n :], 95)),
            }
        )
    print(json.dumps({"motion": args.motion, "seconds": args.seconds, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
