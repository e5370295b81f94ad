"""``mocapkit robot``: the humanoids mocapkit can retarget onto.

mocapkit robot list [--json]
"""

from __future__ import annotations

import argparse
from typing import Any

from mocapkit.cli.common import EXIT_OK, print_json


def _list(args: argparse.Namespace) -> int:
    from mocapkit.errors import MocapkitError
    from mocapkit.retarget.robot_spec import load_robot_spec, packaged_robots

    rows: dict[str, dict[str, object]] = {}
    for name, path in sorted(packaged_robots().items()):
        try:
            spec = load_robot_spec(name)
            rows[name] = {
                "description": spec.description,
                "urdf": str(spec.urdf),
                "available": spec.urdf.is_file(),
                "floating_base": spec.floating_base,
                "keypoints": [k.segment for k in spec.keypoints],
                "yaml": str(path),
            }
        except MocapkitError as exc:
            rows[name] = {"available": False, "why": str(exc), "yaml": str(path)}
    if args.json:
        print_json(rows)
    else:
        for name, r in rows.items():
            why = str(r.get("why", "URDF missing"))
            state = "" if r["available"] else f"  (not available: {why})"
            print(f"{name:12s} {r.get('description', '')}{state}")
    return EXIT_OK


def register(sub: Any) -> None:
    p = sub.add_parser(
        "robot",
        help="humanoid robots for retargeting: list them",
        epilog="example: mocapkit robot list --json",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    cmds = p.add_subparsers(dest="robot_command", metavar="SUBCOMMAND")
    ls = cmds.add_parser(
        "list",
        help="the packaged robots (any --robot also takes a YAML path)",
        epilog="example: mocapkit robot list --json",
    )
    ls.add_argument("--json", action="store_true", help="one JSON object on stdout")
    ls.set_defaults(func=_list)
