"""``mocapkit retarget``: a recording onto a humanoid.

mocapkit retarget INPUT --robot g1 -o robot.csv [--json]

INPUT: a marker trial (C3D/TRC, reconstructed on the way), joint angles (.mot/.sto on
OpenSim's coordinate names), a BVH, or an inertial recording (through the body model). The robot:
a packaged name (``mocapkit robot list``) or a YAML file (docs/robots.md).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from mocapkit.cli.common import EXIT_OK, print_json, process_seconds

_EXAMPLES = """\
examples:
  mocapkit retarget ../shared/data/opensim/gait2392/subject01_walk1.trc --robot g1 \\
      --height 1.8 -o walk_g1.csv --json
  mocapkit retarget angles.mot --robot talos -o walk_talos.npz
  mocapkit retarget walk.c3d --robot my_robot.yaml -o out.csv
"""


def _cmd(args: argparse.Namespace) -> int:
    from mocapkit.retarget.run import Retargeted, check_output, retarget, write_trajectory
    from mocapkit.retarget.streamed import StreamedRetarget, retarget_streamed, streamable

    if args.output:
        check_output(Path(args.output))  # before the work, not after it
    collisions = {
        "check_collisions": not args.no_collision_check,
        "avoid_collisions": args.avoid_collisions,
        "guard_collisions": not args.allow_collisions,
    }
    res: Retargeted | StreamedRetarget
    if streamable(args.input):  # angles, orientations, markers: in pieces, flat memory
        res = retarget_streamed(args.input, args.robot, args.output, preset=args.preset,
                                height_m=args.height, **collisions)  # fmt: skip
    else:
        res = retarget(args.input, args.robot, height_m=args.height, preset=args.preset,
                       **collisions)  # fmt: skip
        if args.output:
            write_trajectory(args.output, res)
    seconds = process_seconds()  # the whole command, as the user's stopwatch sees it
    n = res.frames
    f = res.figures
    report = {
        "robot": res.robot.spec.name,
        "input": str(args.input),
        "frames": n,
        "seconds": round(seconds, 3),
        "fps": round(n / seconds, 1) if seconds > 0 else None,
        "solve_fps": round(n / res.solve_seconds, 1) if res.solve_seconds else None,
        "keypoint_rmse_mm": f["keypoint_rmse_mm"],
        "foot_skate_mm": f["foot_skate_mm"],
        "contact_frames": f["contact_frames"],
        "ground_penetration": f["ground_penetration"],
        "limit_violations": f["limit_violations"],
        "collisions": f["collisions"],
        "held_frames": f["held_frames"],
        "collision_guard": {
            "steered": res.steered,
            "stopped_short": res.stopped_short,
        },
        "notes": res.notes,
        "output": args.output,
    }
    for note in res.notes:
        print(f"warning: {note}", file=sys.stderr)
    if args.json:
        print_json(report)
    else:
        kp = f["keypoint_rmse_mm"]
        print(
            f"{report['robot']}: {n} frames in {seconds:.2f} s ({report['fps']} frames/s end to "
            f"end); keypoints {kp.get('mean')} mm RMS, foot skate {f['foot_skate_mm']} mm/frame,"
            f" limit violations {f['limit_violations']}, collision frames "
            f"{f['collisions']['frames']}",
            file=sys.stderr,
        )
    return EXIT_OK


def register(sub: Any) -> None:
    p = sub.add_parser(
        "retarget",
        help="a recording (markers, joint angles, IMUs) onto a humanoid robot",
        description=__doc__.split("\n\n", 2)[2],
        epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "input", help="C3D/TRC marker trial, .mot/.sto joint angles, a BVH, or an IMU recording"
    )
    p.add_argument("--robot", required=True, help="packaged robot name or a robot YAML file")
    p.add_argument(
        "-o",
        "--output",
        help="robot trajectory: .csv, .npz or .mcap (Foxglove: joints, frame tree)",
    )
    p.add_argument("--height", type=float, help="subject height [m] (marker trials)")
    p.add_argument(
        "--preset", default="full_body_15", help="sensor tree for an IMU recording (body presets)"
    )
    p.add_argument(
        "--no-collision-check", action="store_true", help="skip counting self-collisions"
    )
    p.add_argument(
        "--avoid-collisions",
        action="store_true",
        help="also keep spheres around the robot's bodies apart in every frame's QP "
        "(smoother near contact; ~3x slower)",
    )
    p.add_argument(
        "--allow-collisions",
        action="store_true",
        help="turn off the collision guard (default on: every frame checked on the meshes, "
        "a colliding step steered round or stopped short); collisions are then counted "
        "and warned",
    )
    p.add_argument("--json", action="store_true", help="one JSON object on stdout")
    p.set_defaults(func=_cmd)
