"""``mocapkit body identify``: which sensor is on which segment, from a short motion.

mocapkit body identify RECORDING --preset full_body_16 [--known SEGMENT=SENSOR] [-o map.json]

Raw samples go through a filter (polaris-body; 9D with a magnetometer, else 6D) and their
accelerometers add the joint-centre evidence; a recording with only orientations (an
OpenSense .sto) is identified from them alone. Exit status 1 when some placement cannot
be told (the reasons are printed); ``-o`` writes ``{segment: sensor}`` for ``mocapkit body
angles --map-file``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from mocapkit.body.recordings import FORMATS, load_for_identify
from mocapkit.cli.common import EXIT_ERROR, EXIT_OK, print_json, process_seconds
from mocapkit.errors import ConfigError


def _cmd_identify(args: argparse.Namespace) -> int:
    from mocapkit.body.identify import identify
    from mocapkit.body.pipeline import crop
    from mocapkit.body.sensor_tree import SensorTree
    from mocapkit.cli.body_cmd import _parse_map

    tree = SensorTree.from_yaml(args.tree) if args.tree else SensorTree.preset(args.preset)
    oris, raw, headings, used = load_for_identify(
        Path(args.recording), args.format, args.filter, args.mode
    )
    if args.headings != "auto":
        headings = args.headings
    if args.sensors:
        keep = [s.strip() for s in args.sensors.split(",") if s.strip()]
        unknown = sorted(set(keep) - set(oris))
        if unknown:
            raise ConfigError(
                f"--sensors: no sensor(s) {', '.join(unknown)} in the recording; it has "
                f"{', '.join(sorted(oris))}"
            )
        oris = {k: oris[k] for k in keep}
    if args.start is not None or args.stop is not None:
        oris = crop(oris, args.start, args.stop)
    known = _parse_map(args.known) if args.known else None
    result = identify(tree, oris, raw, headings=headings, known=known)
    elapsed = process_seconds()  # the whole command, as the user's stopwatch sees it
    if args.output:
        Path(args.output).write_text(json.dumps(result.mapping, indent=2) + "\n")
    if args.json:
        report = result.to_dict()
        report.update({"input": used, "headings": headings, "seconds": round(elapsed, 3)})
        if args.output:
            report["output"] = args.output
        print_json(report)
    else:
        print(f"{tree.name}: from {used} ({headings} headings), {elapsed:.2f} s", file=sys.stderr)
        for a in result.assignments:
            print(f"  {a.segment:12s} <- {a.sensor:24s} {a.confidence:4.2f}  {a.evidence}")
        maps = " ".join(f"--map {a.segment}={a.sensor}" for a in result.assignments)
        print(f"for body angles: {maps}", file=sys.stderr)
    for why in result.undecided:
        print(f"cannot tell: {why}", file=sys.stderr)
    return EXIT_OK if result.decided else EXIT_ERROR


_EXAMPLE = """\
examples:
  mocapkit body identify ../shared/data/ximu3-lower-body --preset lower_body
  mocapkit body identify ../shared/data/full-body-15-imu/full_body_example_data.mat \\
      --preset full_body_16 -o placement.json --json
  mocapkit body angles RECORDING --preset full_body_16 --map-file placement.json -o angles.mot
"""


def register(sub: Any) -> None:
    p = sub.add_parser(
        "identify",
        help="find which sensor is on which segment (and left from right) from the motion",
        description=__doc__.split("\n\n", 2)[2],
        epilog=_EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("recording", help="recording file or export directory")
    p.add_argument(
        "--format",
        choices=FORMATS,
        default="auto",
        help="recording format (default: from the name)",
    )
    tree = p.add_mutually_exclusive_group()
    tree.add_argument("--preset", default="full_body_15", help="built-in tree (see 'body presets')")
    tree.add_argument("--tree", help="sensor tree YAML file")
    p.add_argument(
        "--filter",
        default="polaris-body",
        help="orientation filter for the raw samples, or 'device' for the devices' own "
        "orientations (default: polaris-body)",
    )
    p.add_argument(
        "--mode", choices=("9d", "6d"), help="with a filter (default: 9d with a magnetometer)"
    )
    p.add_argument(
        "--headings",
        choices=("auto", "shared", "independent"),
        default="auto",
        help="whether the sensors share one heading (9D) or each has its own (6D); "
        "auto: from the filter mode",
    )
    p.add_argument(
        "--sensors", help="comma-separated sensors to use (default: all in the recording)"
    )
    p.add_argument(
        "--known", action="append", metavar="SEGMENT=SENSOR", help="pin a sensor you know"
    )
    p.add_argument("--start", type=float, help="ignore samples before this time [s]")
    p.add_argument(
        "--end", "--stop", dest="stop", type=float, help="ignore samples after this time [s]"
    )
    p.add_argument("-o", "--output", help="write {segment: sensor} (JSON) for --map-file")
    p.add_argument("--json", action="store_true", help="one JSON object on stdout")
    p.set_defaults(func=_cmd_identify)
