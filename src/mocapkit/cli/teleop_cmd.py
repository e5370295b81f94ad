"""``mocapkit teleop``: evaluation, robot server, live session, playback."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from mocapkit.cli.common import EXIT_OK, print_json

_EXAMPLES = """\
examples:
  mocapkit teleop evaluate --shape circle --json
  mocapkit teleop evaluate --shape all --plot fig9.png --record trials.mcap
  mocapkit teleop server --port 9870 --robot robonaut2-right --latency-ms 30
  mocapkit teleop playback trials.mcap --server 127.0.0.1:9870 --seconds 20
"""


def register(sub: Any) -> None:
    p = sub.add_parser(
        "teleop",
        help="robot teleoperation: six-shape evaluation, robot server, playback",
        description="Robot teleoperation (Miller et al., sections 5-6).",
        epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    tsub = p.add_subparsers(dest="teleop_command", metavar="SUBCOMMAND")

    ev = tsub.add_parser(
        "evaluate",
        help="the paper's six-shape evaluation, end to end, in real time",
        epilog="example: mocapkit teleop evaluate --shape infinity --json",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ev.add_argument(
        "--shape",
        default="circle",
        choices=["vertical", "horizontal", "diagonal", "circle", "box", "infinity", "all"],
    )
    ev.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    ev.add_argument("--seed", type=int, default=0, help="noise and mounting seed")
    ev.add_argument("--shape-seconds", type=float, default=6.0, help="duration of the shape")
    ev.add_argument("--latency-ms", type=float, default=30.0, help="robot actuation latency")
    ev.add_argument("--plot", type=Path, default=None, help="write a Fig. 9-like PNG")
    ev.add_argument("--record", type=Path, default=None, help="write commands to an MCAP file")
    ev.set_defaults(func=_evaluate)

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
        epilog="example: mocapkit teleop playback trials.mcap --server 127.0.0.1:9870",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    pb.add_argument("recording", type=Path, help="MCAP file with /teleop/command")
    pb.add_argument("--server", default="127.0.0.1:9870", help="robot server HOST:PORT")
    pb.add_argument("--seconds", type=float, default=10.0, help="how long to play")
    pb.add_argument("--rate-hz", type=float, default=100.0)
    pb.add_argument("--json", action="store_true")
    pb.set_defaults(func=_playback)


def _address(text: str) -> tuple[str, int]:
    host, _, port = text.rpartition(":")
    return (host or "127.0.0.1", int(port))


def _evaluate(args: argparse.Namespace) -> int:
    from mocapkit.teleop.evaluate import evaluate_shape, plot_shapes
    from mocapkit.teleop.operator import SHAPES
    from mocapkit.teleop.server import ServerConfig

    shapes = list(SHAPES) if args.shape == "all" else [args.shape]
    cfg = ServerConfig(latency_s=args.latency_ms / 1e3)
    results = []
    for shape in shapes:
        r = evaluate_shape(shape, seed=args.seed, shape_s=args.shape_seconds, server=cfg)
        results.append(r)
        if not args.json:
            print(r.summary())
        print(f"{shape}: {'; '.join(r.transitions)}", file=sys.stderr)
    if args.plot is not None:
        plot_shapes(results, args.plot)
    if args.record is not None:
        from mocapkit.teleop.recording import TeleopRecorder

        with TeleopRecorder(args.record) as rec:
            r = results[0]
            for row in r.commanded:
                rec.command(float(row[0]), row[1:4], [1.0, 0.0, 0.0, 0.0])
            for row in r.achieved:
                rec.report(float(row[0]), row[1:4], [1.0, 0.0, 0.0, 0.0])
    if args.json:
        out = results[0].summary() if len(results) == 1 else [r.summary() for r in results]
        print_json(out)
    return EXIT_OK


def _server(args: argparse.Namespace) -> int:
    from mocapkit.teleop.server import run_from_args

    return run_from_args(args)


def _playback(args: argparse.Namespace) -> int:
    from mocapkit.robot.model import pose_matrix
    from mocapkit.teleop.link import RobotLink
    from mocapkit.teleop.recording import loop_trajectory, playback_pose, read_commands
    from mocapkit.teleop.session import TeleopSession

    traj, check = loop_trajectory(read_commands(args.recording))
    print(
        f"seam {check.seam_pos_m * 1e3:.1f} mm, {check.seam_rot_rad * 57.3:.1f} deg: "
        f"{'looping' if check.loops else 'playing once'}",
        file=sys.stderr,
    )
    session = TeleopSession()
    sent = 0
    with RobotLink(_address(args.server)) as link:
        link.send_hold()
        if not link.wait_for_report(5.0):
            from mocapkit.errors import MocapkitError

            raise MocapkitError(f"no robot server answers at {args.server}")
        start = time.monotonic()
        session.engage(start)
        period = 1.0 / args.rate_hz
        while (now := time.monotonic()) - start < args.seconds:
            pos, quat = playback_pose(traj, now - start, check.loops)
            link.poll()
            out = session.tick(now, pose_matrix(pos, quat), link.robot_pose(), link.report_age(now))
            if out.command is not None:
                link.send_command(out.command)
                sent += 1
            elif out.hold:
                link.send_hold()
            time.sleep(period)
        link.send_hold()
    summary = {
        "loops": check.loops,
        "seam_mm": check.seam_pos_m * 1e3,
        "commands_sent": sent,
        "transitions": [
            f"{t.source.value}->{t.target.value}: {t.reason}" for t in session.transitions
        ],
    }
    if args.json:
        print_json(summary)
    return EXIT_OK
