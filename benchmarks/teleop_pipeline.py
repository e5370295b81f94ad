"""Host-side pipeline time, packet -> robot command, and the six-shape evaluation.

    python -m benchmarks.teleop_pipeline            # pipeline timing + six shapes
    python -m benchmarks.teleop_pipeline --no-shapes

Pipeline: 15 sensors at 100 Hz (one packet per hub round carrying all 15 orientations);
the arm's two sensors drive Robonaut 2 (eq. 16 retargeting, intermediate model FK,
session, command encoded and sent on a real loopback UDP socket to a listener).
"""

from __future__ import annotations

import argparse
import json
import socket
import time

import numpy as np

from mocapkit.robot import robonaut2_arm
from mocapkit.robot.segment_retarget import (
    SegmentRetargeter,
    robonaut2_groups,
    robonaut2_init_posture,
)
from mocapkit.teleop.link import RobotLink
from mocapkit.teleop.operator import SHAPES
from mocapkit.teleop.pipeline import ArmTeleop, OrientationSample
from mocapkit.teleop.session import TeleopSession


def pipeline_timing(n_packets: int = 3000, n_sensors: int = 15) -> dict[str, float]:
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.setblocking(False)
    arm = robonaut2_arm("right")
    rt = SegmentRetargeter(arm, robonaut2_groups("right")[:2], robonaut2_init_posture("right"))
    session = TeleopSession()
    with RobotLink(rx.getsockname()) as link:
        pipe = ArmTeleop(arm, rt, {1: "humerus_r", 2: "radius_r"}, session, link)
        pipe.keep_frames = False
        ident = np.array([1.0, 0.0, 0.0, 0.0])
        pipe.calibrate(dict.fromkeys(range(1, n_sensors + 1), ident))
        # the robot's pose (a report would carry it): the model's own, so it engages
        from mocapkit.robot.model import pose_parts
        from mocapkit.teleop import protocol as proto

        pos, quat = pose_parts(pipe.model_pose()[1])
        rng = np.random.default_rng(0)
        lat = []
        session.engage(time.monotonic())
        for k in range(n_packets):
            link.latest = proto.Report(
                k, 0, pos, quat, 0, proto.Gate.SYNCED, proto.Reason.OK, np.zeros(7)
            )
            link.latest_t = time.monotonic()
            wob = rng.normal(0, 0.01, (n_sensors, 3))
            quats = np.column_stack([np.ones(n_sensors), wob])
            quats /= np.linalg.norm(quats, axis=1, keepdims=True)
            arrival = time.perf_counter_ns()
            samples = [OrientationSample(i + 1, arrival, quats[i]) for i in range(n_sensors)]
            f = pipe.process(samples)
            if f.latency_ns is not None:
                lat.append(f.latency_ns / 1e6)
            try:
                while True:
                    rx.recv(4096)
            except BlockingIOError:
                pass
            time.sleep(0.002)
    rx.close()
    a = np.array(lat)
    return {"packets": len(a), "p50_ms": float(np.percentile(a, 50)),
            "p99_ms": float(np.percentile(a, 99)), "max_ms": float(a.max())}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--no-shapes", action="store_true")
    args = ap.parse_args()
    print(json.dumps({"pipeline_15_sensors": pipeline_timing()}, indent=2))
    if not args.no_shapes:
        from mocapkit.teleop.evaluate import evaluate_shape

        for shape in SHAPES:
            print(json.dumps(evaluate_shape(shape).summary()))


if __name__ == "__main__":
    main()
