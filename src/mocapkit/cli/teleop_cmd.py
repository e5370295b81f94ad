"""``mocapkit teleop``: evaluation, live session, robot server, playback."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import Any

from mocapkit.cli.boundary import port
from mocapkit.cli.common import EXIT_OK, print_json, progress

_EXAMPLES = """\
examples:
  mocapkit teleop evaluate --shape circle --json
  mocapkit teleop evaluate --shape all --plot fig9.png --record trial.mcap
  mocapkit teleop evaluate --shape box --chain ideal --json      # ablation: no IMU, no filters
  mocapkit teleop run --suit-port 9000 --control-port 9871 --keys --record session.mcap
  mocapkit teleop server --port 9870 --robot robonaut2-right --latency-ms 30
  mocapkit teleop playback trial-circle.mcap --server 127.0.0.1:9870 --seconds 20
"""
_SHAPES = ["vertical", "horizontal", "diagonal", "circle", "box", "infinity"]


def _pipeline_args(p: argparse.ArgumentParser) -> None:
    from mocapkit.imu.filters import available_filters

    p.add_argument("--preset", default="right_arm_2", help="body sensor tree")
    p.add_argument(
        "--robot",
        default="robonaut2-right",
        help="robot arm (intermediate model, end-effector commands), or a humanoid name or "
        "robot YAML (mocapkit robot list: whole-body joint commands)",
    )
    p.add_argument(
        "--retarget",
        default="segments",
        choices=["segments", "map"],
        help="segments: eq. 16 along the robot's axes (default); map: the YAML joint map",
    )
    p.add_argument(
        "--fusion",
        default="node",
        choices=["node", "host"],
        help="node: orientations fused on the sensor nodes (default); host: RAW samples fused here",
    )
    p.add_argument(
        "--filter",
        default="miller",
        choices=available_filters(),
        help="host-side orientation filter (default: the most accurate for the chain)",
    )
    p.add_argument("--latency-ms", type=float, default=30.0, help="robot actuation latency")


def register(sub: Any) -> None:
    p = sub.add_parser(
        "teleop",
        help="robot teleoperation: six-shape evaluation, live session, robot server, playback",
        description="Robot teleoperation (Miller et al., sections 5-6).",
        epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    tsub = p.add_subparsers(dest="teleop_command", metavar="SUBCOMMAND")

    ev = tsub.add_parser(
        "evaluate",
        help="the paper's six-shape evaluation through the whole chain, in real time",
        epilog="example: mocapkit teleop evaluate --shape infinity --json",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ev.add_argument(
        "--shape",
        default="circle",
        choices=[*_SHAPES, "all"],
        help="the shape(s) to trace (default: all six)",
    )
    ev.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    ev.add_argument(
        "--chain",
        default="real",
        choices=["real", "ideal"],
        help="real: IMU signals, filters, suit packets (default); ideal: an ablation with "
        "the true orientations on the wire",
    )
    ev.add_argument("--seed", type=int, default=0, help="sensor errors, mountings, heading")
    ev.add_argument("--shape-seconds", type=float, default=6.0, help="duration of the shape")
    ev.add_argument(
        "--no-mag-calibration", action="store_true", help="skip the magnetometer calibration"
    )
    _pipeline_args(ev)
    ev.add_argument("--plot", type=Path, default=None, help="write a Fig. 9-like PNG")
    ev.add_argument(
        "--record",
        type=Path,
        default=None,
        help="record the session (MCAP: full poses, joints, transitions); with --shape all "
        "one file per shape, NAME-SHAPE.mcap",
    )
    ev.set_defaults(func=_evaluate)

    rn = tsub.add_parser(
        "run",
        help="a live session from a suit stream (UDP), with operator controls",
        epilog="keys (one per line): c calibrate, e engage, d disengage, r reindex, Enter "
        "clutch toggle, s status, q quit.\n"
        "example: mocapkit teleop run --suit-port 9000 --keys --record session.mcap",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    rn.add_argument("--suit-host", default="127.0.0.1", help="address to receive the suit on")
    rn.add_argument("--suit-port", type=port, default=9000, help="UDP port of the suit stream")
    rn.add_argument(
        "--server", default=None, help="robot server HOST:PORT (default: start one here)"
    )
    rn.add_argument("--seconds", type=float, default=None, help="stop after this long")
    rn.add_argument(
        "--commands", default="", help="scheduled commands, e.g. '1.0:calibrate,3.5:engage'"
    )
    rn.add_argument("--control-port", type=port, default=None, help="UDP control socket port")
    rn.add_argument("--keys", action="store_true", help="read commands from stdin lines")
    rn.add_argument("--record", type=Path, default=None, help="record the session (MCAP)")
    rn.add_argument(
        "--foxglove-port",
        type=port,
        default=None,
        help="serve the live session to Foxglove (WebSocket, foxglove-sdk) on this loopback "
        "port: body frames, robot joints, session state",
    )
    rn.add_argument(
        "--lsl",
        action="store_true",
        help="LSL outlets (pylsl): mocapkit-joint-angles and mocapkit-orientations, one "
        "sample per frame; with --fusion host also mocapkit-imu-<sensor>, every raw sample",
    )
    rn.add_argument(
        "--ros2-zenoh",
        default=None,
        metavar="ENDPOINTS",
        help="publish ROS 2 JointState topics over Zenoh in rmw_zenoh's format to these "
        "comma-separated endpoints (a ROS machine's rmw_zenohd, e.g. tcp/127.0.0.1:7447; "
        "'' for Zenoh's scouting)",
    )
    rn.add_argument(
        "--robot-link",
        choices=("server", "ros2"),
        default="server",
        help="server: mocapkit's robot server (UDP; default); ros2: a ROS 2 robot over the "
        "--ros2-zenoh endpoints: a humanoid (--robot g1, ...) gets joint targets on "
        "--ros2-command-topic and reports --ros2-state-topic; an arm (robonaut2-right) gets "
        "end-effector poses for its own IK on --ros2-pose-topic and reports "
        "--ros2-pose-state-topic",
    )
    rn.add_argument(
        "--ros2-pose-topic",
        default="/target_pose",
        help="with --robot-link ros2 and an arm: geometry_msgs/PoseStamped targets",
    )
    rn.add_argument(
        "--ros2-pose-state-topic",
        default="/current_pose",
        help="with --robot-link ros2 and an arm: the robot's end-effector PoseStamped",
    )
    rn.add_argument(
        "--ros2-frame",
        default="base",
        help="with --robot-link ros2 and an arm: frame_id of the targets (the arm's base)",
    )
    rn.add_argument(
        "--ros2-command-topic",
        default="/forward_position_controller/commands",
        help="with --robot-link ros2: std_msgs/Float64MultiArray targets (ros2_control's "
        "forward command controller)",
    )
    rn.add_argument(
        "--ros2-state-topic",
        default="/joint_states",
        help="with --robot-link ros2: the robot's sensor_msgs/JointState",
    )
    rn.add_argument(
        "--ros2-joints",
        default=None,
        help="with --robot-link ros2: the controller's joints in its order, comma-separated "
        "(default: the robot model's)",
    )
    rn.add_argument("--calibrate-seconds", type=float, default=1.0, help="calibration hold")
    rn.add_argument(
        "--robot-key-file",
        default=None,
        help="shared key of a robot server off this machine (its --key-file): signed link",
    )
    rn.add_argument("--json", action="store_true", help="print the final summary as JSON")
    _pipeline_args(rn)
    rn.set_defaults(func=_run)

    sv = tsub.add_parser(
        "server",
        help="run the simulated robot server (a separate process) until Ctrl-C",
        epilog="example: mocapkit teleop server --port 9870 --latency-ms 30",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    from mocapkit.teleop.server import config_args

    config_args(sv)
    sv.set_defaults(func=_server)

    pb = tsub.add_parser(
        "playback",
        help="play a recorded motion on the robot, looping when it begins and ends together",
        epilog="example: mocapkit teleop playback trial.mcap --server 127.0.0.1:9870",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    pb.add_argument("recording", type=Path, help="MCAP file with /teleop/command")
    pb.add_argument("--server", default="127.0.0.1:9870", help="robot server HOST:PORT")
    pb.add_argument("--seconds", type=float, default=10.0, help="how long to play")
    pb.add_argument(
        "--rate-hz", type=float, default=100.0, help="command rate of the playback [Hz]"
    )
    pb.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    pb.set_defaults(func=_playback)


def _address(text: str) -> tuple[str, int]:
    from mocapkit.errors import ConfigError

    host, _, number = text.rpartition(":")
    if not number.isdigit() or not 0 < int(number) <= 65535:
        raise ConfigError(
            f"server: expected HOST:PORT like 127.0.0.1:9870 (port 1..65535), got {text!r}"
        )
    return (host or "127.0.0.1", int(number))


def _pipeline_config(args: argparse.Namespace, fusion: str) -> Any:
    from mocapkit.teleop.pipeline import PipelineConfig

    return PipelineConfig(
        preset=args.preset,
        robot=args.robot,
        retarget=args.retarget,
        fusion=fusion,  # type: ignore[arg-type]
        filter_name=args.filter,
    )


def _evaluate(args: argparse.Namespace) -> int:
    from mocapkit.teleop.evaluate import evaluate_shape, plot_shapes
    from mocapkit.teleop.operator_suit import SuitSetup
    from mocapkit.teleop.server import ServerConfig

    shapes = _SHAPES if args.shape == "all" else [args.shape]
    suit = SuitSetup(
        chain=args.chain,
        fusion=args.fusion,
        filter_name=args.filter,
        mag_calibration=not args.no_mag_calibration,
    )
    server = ServerConfig(robot=args.robot, latency_s=args.latency_ms / 1e3)
    results = []
    for shape in progress(shapes, "teleop evaluate", total=len(shapes)):
        record = args.record
        if record is not None and len(shapes) > 1:
            record = record.with_name(f"{record.stem}-{shape}{record.suffix or '.mcap'}")
        r = evaluate_shape(
            shape,
            suit=suit,
            pipeline=_pipeline_config(args, args.fusion),
            server=server,
            seed=args.seed,
            shape_s=args.shape_seconds,
            record=record,
        )
        results.append(r)
        if not args.json:
            print({**r.summary(), **{k: v for k, v in r.details.items() if k != "human_rmse_deg"}})
        print(f"{shape}: {'; '.join(r.transitions)}", file=sys.stderr)
        print(f"{shape}: details {r.details}", file=sys.stderr)
    if args.plot is not None:
        plot_shapes(results, args.plot)
    if args.json:
        out = results[0].summary() if len(results) == 1 else [r.summary() for r in results]
        print_json(out)
    return EXIT_OK


def _run(args: argparse.Namespace) -> int:
    from mocapkit.teleop.live import LiveConfig
    from mocapkit.teleop.run import Ros2RobotOptions, RunOptions, parse_commands, run_live
    from mocapkit.teleop.server import ServerConfig, read_key

    logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(name)s: %(message)s")
    config = LiveConfig(
        pipeline=_pipeline_config(args, args.fusion),
        suit_host=args.suit_host,
        suit_port=args.suit_port,
        calibrate_s=args.calibrate_seconds,
        robot_key=read_key(args.robot_key_file),
    )
    options = RunOptions(
        server=None if args.server is None else _address(args.server),
        spawn=ServerConfig(robot=args.robot, latency_s=args.latency_ms / 1e3),
        seconds=args.seconds,
        commands=parse_commands(args.commands),
        control_port=args.control_port,
        keys=sys.stdin if args.keys else None,
        record=args.record,
        foxglove_port=args.foxglove_port,
        lsl=args.lsl,
        ros2_zenoh=None
        if args.ros2_zenoh is None
        else tuple(e for e in args.ros2_zenoh.split(",") if e),
        ros2_robot=None
        if args.robot_link != "ros2"
        else Ros2RobotOptions(
            command_topic=args.ros2_command_topic,
            state_topic=args.ros2_state_topic,
            controller_joints=None
            if args.ros2_joints is None
            else tuple(j.strip() for j in args.ros2_joints.split(",") if j.strip()),
            pose_topic=args.ros2_pose_topic,
            pose_state_topic=args.ros2_pose_state_topic,
            frame_id=args.ros2_frame,
        ),
    )
    summary = run_live(config, options)
    if args.json:
        print_json(summary)
    else:
        print(
            f"state {summary['state']}, {summary['commands_sent']} commands, pipeline "
            f"p50 {summary['pipeline_ms_p50']:.3f} ms p99 {summary['pipeline_ms_p99']:.3f} ms"
        )
    return EXIT_OK


def _server(args: argparse.Namespace) -> int:
    from mocapkit.teleop.server import run_from_args

    return run_from_args(args)


def _playback(args: argparse.Namespace) -> int:
    from mocapkit.teleop.playback import play_recording

    summary = play_recording(
        args.recording, _address(args.server), seconds=args.seconds, rate_hz=args.rate_hz
    )
    print(
        f"seam {summary['seam_mm']:.1f} mm: {'looped' if summary['loops'] else 'played once'}, "
        f"{summary['commands_sent']} commands, tracking {summary['tracking_rmse_mm']:.1f} mm",
        file=sys.stderr,
    )
    if args.json:
        print_json(summary)
    return EXIT_OK
