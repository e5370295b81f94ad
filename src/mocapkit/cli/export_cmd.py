"""``mocapkit export``: recordings and results into other tools' formats (ROS 2 bags)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from mocapkit.cli.common import EXIT_OK, print_json

_EXAMPLES = """\
examples:
  mocapkit export ros2 ../shared/data/ximu3-lower-body -o lower_body_bag --filter polaris
  mocapkit export ros2 walk.mot -o walk_bag --storage mcap

An IMU recording (any format 'imu run' reads) becomes sensor_msgs/Imu on /imu/<sensor>
(with --filter, the orientation that filter estimates; without, none, as REP 145 marks
it) and sensor_msgs/MagneticField; a .mot of joint angles becomes sensor_msgs/JointState
on /joint_states. 'ros2 bag play BAG' replays it; no ROS install is needed to write it.
"""


def register(sub: Any) -> None:
    p = sub.add_parser(
        "export",
        help="recordings and results into other tools' formats (ROS 2 bags)",
        epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    cmds = p.add_subparsers(dest="export_command", metavar="FORMAT")
    ros = cmds.add_parser(
        "ros2", help="a ROS 2 bag (rosbag2, SQLite3 or MCAP storage)", epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    ros.add_argument("path", help="an IMU recording (file or directory) or a .mot")
    ros.add_argument("-o", "--output", required=True, help="the bag directory to create")
    ros.add_argument("--filter", default=None, help="add orientations from this filter (IMU)")
    ros.add_argument("--mode", choices=["9d", "6d"], default="9d", help="filter mode")
    ros.add_argument(
        "--storage",
        choices=["sqlite3", "mcap"],
        default="sqlite3",
        help="rosbag2 storage: sqlite3 (default) or mcap",
    )
    ros.add_argument("--json", action="store_true", help="print one JSON summary")
    ros.set_defaults(func=_ros2)


def _ros2(args: argparse.Namespace) -> int:
    from mocapkit.io.ros2bag import write_imu_bag, write_joint_state_bag

    src = Path(args.path)
    if src.suffix.lower() == ".mot":
        from mocapkit.io.joint_angles_mot import read_joint_angles_mot

        angles = read_joint_angles_mot(src)
        write_joint_state_bag(args.output, angles, storage=args.storage)
        summary = {"bag": args.output, "topics": ["/joint_states"], "messages": len(angles.time)}
    else:
        from mocapkit.imu.filters import make_filter
        from mocapkit.io.imu_files import read_imu_recordings

        recs = read_imu_recordings(src)
        oris = None
        if args.filter is not None:
            oris = {
                name: make_filter(args.filter, rec.rate_hz).run_recording(
                    rec, use_mag=args.mode == "9d"
                )
                for name, rec in recs.items()
            }
        write_imu_bag(args.output, recs, oris, storage=args.storage)
        summary = {
            "bag": args.output,
            "topics": [f"/imu/{'_'.join(n.split())}" for n in recs],
            "messages": sum(r.n_samples for r in recs.values()),
        }
    if args.json:
        print_json(summary)
    else:
        print(f"wrote {args.output} ({summary['messages']} messages)", file=sys.stderr)
    return EXIT_OK
