"""Host-side pipeline time (packet -> robot command) and the six-shape evaluation, through
the real chain.

    python -m benchmarks.teleop_pipeline                  # everything below (~5 min)
    python -m benchmarks.teleop_pipeline --only pipeline  # the 15-sensor timing only
    python -m benchmarks.teleop_pipeline --only fusion    # host-side fusion per round
    python -m benchmarks.teleop_pipeline --only shapes --filter bachmann

1. ``pipeline``: 15 sensors at 100 Hz (the ``full_body_15`` tree, the paper's maximum),
   end to end on real sockets: the simulated suit in its own process sends one bundle per
   hub round (``--fusion node``) or 15 RAW datagrams per round (``--fusion host``: 15
   filter updates per round on the host), the live session's receiver thread runs the
   whole per-packet path (decode, sequencing, fusion, body model for 15 segments,
   retargeting, forward kinematics, session, send) and a robot-server process answers.
   ``pipeline_ms`` = the receiver's arrival stamp of the oldest contributing packet ->
   the command's send, over every command of the run. Also the per-packet CPU cost of
   ``TeleopPipeline.process`` alone, paced at 100 Hz in one process (no sockets but the
   robot link's).
2. ``fusion``: host-side fusion of one round of 15 RAW samples, the filter bank against
   one still-start filter object per sensor.
3. ``shapes``: the six shapes through the real chain (``right_arm_2``, the paper's two
   sensors; consumer-grade IMU errors; on-node filters), with the ideal chain (the true
   orientations on the wire) as an ablation.
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import time

import numpy as np

from mocapkit.body.calibration import q_world_ground
from mocapkit.body.joint_angles import compose_pose
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.geometry import quat_exp, quat_mul
from mocapkit.imu.filter_bank import FilterBank
from mocapkit.imu.filters import make_filter
from mocapkit.imu.still_start import StillStartFilter
from mocapkit.robot.model import pose_parts
from mocapkit.suit.protocol import Kind
from mocapkit.suit.samples import SuitSample
from mocapkit.teleop import protocol as proto
from mocapkit.teleop.evaluate import evaluate_shape
from mocapkit.teleop.link import RobotLink
from mocapkit.teleop.operator import SHAPES
from mocapkit.teleop.operator_suit import SuitSetup
from mocapkit.teleop.pipeline import PipelineConfig, TeleopPipeline
from mocapkit.teleop.session import TeleopSession


def process_cost(n_packets: int = 3000, preset: str = "full_body_15") -> dict[str, float]:
    """``TeleopPipeline.process`` per packet [us], paced at 100 Hz in one process."""
    tree = SensorTree.preset(preset)
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.setblocking(False)
    session = TeleopSession()
    with RobotLink(rx.getsockname()) as link:
        pipe = TeleopPipeline(PipelineConfig(preset=preset), session, link)
        pose = {c: np.pi / 2 for c in ("pro_sup_r", "pro_sup_l") if c in tree.coordinate_names}
        q0 = quat_mul(q_world_ground(0.3), compose_pose(tree, pose))
        n = len(tree.segments)
        t0 = time.monotonic()
        pipe.start_calibration(t0, 0.05)
        while pipe.body is None:
            now = time.monotonic()
            pipe.ingest(
                [SuitSample(i + 1, 0, 0.0, 0, Kind.ORIENTATION, q0[i]) for i in range(n)], now
            )
            time.sleep(0.005)
        now = time.monotonic()  # fresh data: a loaded machine may have slept > 0.1 s
        pipe.ingest([SuitSample(i + 1, 0, 0.0, 0, Kind.ORIENTATION, q0[i]) for i in range(n)], now)
        T, fault = pipe.model_pose(now)
        assert T is not None, fault
        pos, quat = pose_parts(T)
        session.engage(time.monotonic())
        rng = np.random.default_rng(0)
        cost = []
        for k in range(n_packets):
            link.latest = proto.Report(
                k, 0, pos, quat, 0, proto.Gate.SYNCED, proto.Reason.OK, np.zeros(7)
            )
            link.latest_t = time.monotonic()
            wobble = quat_exp(rng.normal(0, 0.002, (n, 3)))
            q = quat_mul(q0, wobble)
            arrival = time.perf_counter_ns()
            samples = [
                SuitSample(i + 1, k, k * 0.01, arrival, Kind.ORIENTATION, q[i]) for i in range(n)
            ]
            t = time.perf_counter_ns()
            frame = pipe.process(samples, arrival)
            cost.append((time.perf_counter_ns() - t) / 1e3)
            assert frame is not None
            assert frame.command is not None
            try:
                while True:
                    rx.recv(4096)
            except BlockingIOError:
                pass
            time.sleep(0.01)
    rx.close()
    a = np.array(cost)
    return {"packets": len(a), "p50_us": float(np.percentile(a, 50)),
            "p99_us": float(np.percentile(a, 99)), "max_us": float(a.max())}  # fmt: skip


def fusion_cost(name: str, n_rounds: int = 2000, n_sensors: int = 15) -> dict[str, object]:
    """Host-side fusion of one round (one RAW sample per sensor) [us]: the pipeline's
    ``FilterBank`` (one numba call per round for filters with a bank kernel) against one
    ``StillStartFilter`` per sensor (a Python call per sample), back to back after the
    still start."""
    rng = np.random.default_rng(0)
    acc = np.array([0.0, 0.0, 9.81]) + rng.normal(0, 0.05, (n_rounds, n_sensors, 3))
    mag = np.array([0.0, 20.0, -40.0]) + rng.normal(0, 0.3, (n_rounds, n_sensors, 3))
    gyr = rng.normal(0, 0.005, (n_rounds, n_sensors, 3))
    slots = np.arange(n_sensors)
    bank = FilterBank(name, 100.0, n_sensors, still_s=0.8)
    objs = [StillStartFilter(make_filter(name, 100.0), 0.8) for _ in range(n_sensors)]
    warm = 100  # the still start (80 samples) and the first rounds after it
    t_bank, t_obj = [], []
    for k in range(n_rounds):
        t = time.perf_counter_ns()
        bank.update(slots, gyr[k], acc[k], mag[k])
        t_bank.append(time.perf_counter_ns() - t)
        t = time.perf_counter_ns()
        for i, f in enumerate(objs):
            f.update(gyr[k, i], acc[k, i], mag[k, i])
        t_obj.append(time.perf_counter_ns() - t)
    b, o = np.array(t_bank[warm:]) / 1e3, np.array(t_obj[warm:]) / 1e3
    return {"filter": name, "sensors": n_sensors, "batched": bank.batched,
            "bank_us_p50": float(np.percentile(b, 50)), "bank_us_p99": float(np.percentile(b, 99)),
            "per_sensor_us_p50": float(np.percentile(o, 50)),
            "per_sensor_us_p99": float(np.percentile(o, 99))}  # fmt: skip


def pipeline_15(fusion: str, shape_s: float) -> dict[str, object]:
    r = evaluate_shape(
        "circle",
        suit=SuitSetup(fusion=fusion),  # type: ignore[arg-type]
        pipeline=PipelineConfig(preset="full_body_15"),
        shape_s=shape_s,
    )
    return {"fusion": fusion, **r.summary(), "pipeline_ms_max": r.details["pipeline_ms_max"],
            "commands": r.details["commands"]}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", choices=["pipeline", "fusion", "shapes"], default=None)
    ap.add_argument("--filter", default="miller")
    ap.add_argument("--fusion", default="node", choices=["node", "host"])
    ap.add_argument("--retarget", default="segments", choices=["segments", "map"])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-ideal", action="store_true", help="skip the ideal-chain ablation")
    args = ap.parse_args()
    print(json.dumps({"load_average": os.getloadavg()}))
    if args.only in (None, "fusion"):
        for name in ("miller", "bachmann", "polaris"):
            print(json.dumps({"host_fusion_15_sensors": fusion_cost(name)}))
    if args.only in (None, "pipeline"):
        print(json.dumps({"process_cost_15_sensors": process_cost()}))
        for fusion in ("node", "host"):
            print(json.dumps({"pipeline_15_sensors_100hz": pipeline_15(fusion, 6.0)}))
    if args.only in (None, "shapes"):
        chains = ["real"] if args.no_ideal else ["real", "ideal"]
        for chain in chains:
            for shape in SHAPES:
                suit = SuitSetup(chain=chain, fusion=args.fusion, filter_name=args.filter)  # type: ignore[arg-type]
                r = evaluate_shape(
                    shape,
                    suit=suit,
                    pipeline=PipelineConfig(retarget=args.retarget, filter_name=args.filter),
                    seed=args.seed,
                )
                extra = {
                    k: round(v, 3)
                    for k, v in r.details.items()
                    if k in ("cmd_rmse_mm", "tracking_rmse_mm")
                }
                print(json.dumps({"chain": chain, **r.summary(), **extra}))
    print(json.dumps({"load_average": os.getloadavg()}))


if __name__ == "__main__":
    main()
