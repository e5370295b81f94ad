"""Humanoid teleoperation through the live chain: a simulated suit process (the right
arm, the paper's two sensors), the session's body model, whole-body retargeting and the
JOINTS link to a robot-server process.

    python -m benchmarks.teleop_humanoid [--robots g1,talos] [--write-docs]

Per robot: the operator traces the vertical shape for 6 s after calibrating and engaging;
reported: the host-side pipeline time per command (the oldest sample's arrival to the
JOINTS datagram sent: fusion, body model, retargeting QP with the collision guard,
session), the commands sent, and how far the robot's reported joints trail the commands
(RMS over the engaged time, the server moving at its velocity limits after a 30 ms
actuation latency).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks._docs import write_section


def run(robot: str) -> dict[str, float]:
    from mocapkit.body.sensor_tree import SensorTree
    from mocapkit.teleop.live import LiveConfig, LiveSession
    from mocapkit.teleop.operator import operator_motion
    from mocapkit.teleop.operator_suit import SuitSetup, suit_timeline
    from mocapkit.teleop.pipeline import PipelineConfig
    from mocapkit.teleop.sender import TimelineSender
    from mocapkit.teleop.server import ServerConfig, spawn_robot_server

    motion = operator_motion(
        "vertical", SensorTree.preset("right_arm_2"), calib_s=2.0, reach_s=1.2,
        settle_s=0.6, shape_s=6.0, hold_s=0.5, heading_rad=0.7,
    )  # fmt: skip
    ids = {"upper_arm_r": 1, "forearm_r": 2}
    items, _ = suit_timeline(motion, SuitSetup(), ids, np.random.default_rng(0))
    cfg = LiveConfig(pipeline=PipelineConfig(robot=robot))
    with spawn_robot_server(ServerConfig(robot=robot), max_seconds=120) as srv:
        live = LiveSession(cfg, srv.address, keep_frames=True)
        with live, TimelineSender(items, "127.0.0.1", live.suit_port) as sender:
            while live.link.latest is None:
                time.sleep(0.01)
            t_go = sender.go()
            time.sleep(max(0.0, t_go + motion.calib_window[0] - time.perf_counter()))
            live.calibrate(motion.calib_window[1] - motion.calib_window[0])
            time.sleep(max(0.0, t_go + motion.engage_t - time.perf_counter()))
            live.engage()
            sender.wait(60.0)
            lat = live.pipeline.latency_ms()
            frames = [f for f in live.pipeline.frames if f.state.value == "engaged"]
            sent = [(f.t, f.q_robot) for f in frames if f.q_robot is not None]
            reports = [(t, r.q) for t, r in live.reports]
    t_rep = np.array([t for t, _ in reports])
    lag = []
    for t, q in sent:
        k = int(np.searchsorted(t_rep, t + 0.1))  # the report 100 ms later
        if k < len(reports) and reports[k][1].shape == q.shape:
            lag.append(np.abs(reports[k][1] - q).max())
    return {
        "p50": float(np.percentile(lat, 50)),
        "p99": float(np.percentile(lat, 99)),
        "commands": float(len(lat)),
        "lag_deg": float(np.degrees(np.sqrt(np.mean(np.square(lag))))) if lag else float("nan"),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="g1,talos,romeo,icub")
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    rows = []
    for robot in args.robots.split(","):
        r = run(robot)
        rows.append(f"| {robot} | {r['p50']:.2f} | {r['p99']:.2f} | {r['commands']:.0f} | "
                    f"{r['lag_deg']:.2f} |")  # fmt: skip
        print(rows[-1], flush=True)
    text = (
        "`python -m benchmarks.teleop_humanoid` (method in the module docstring): the live "
        "chain onto a humanoid, suit process -> session -> JOINTS -> robot-server process "
        "on loopback, 100 Hz.\n\n| robot | pipeline p50 ms | p99 ms | JOINTS commands | "
        "robot 100 ms after a command, worst joint RMS [deg] |\n|---|---:|---:|---:|---:|\n"
        + "\n".join(rows)
    )
    print(text)
    if args.write_docs:
        write_section("Teleoperation onto a humanoid (live chain)", text)


if __name__ == "__main__":
    main()
