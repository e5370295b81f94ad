"""``mocapkit body``: sensor orientations -> calibrated segment orientations and joint angles.

mocapkit body presets [--json]
mocapkit body angles RECORDING --preset full_body_15 -o angles.mot [--bvh body.bvh] --json
mocapkit body identify RECORDING --preset full_body_16 -o placement.json
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mocapkit.body.recordings import (
    FORMATS,
    load_orientations,
    read_raw,
    recording_format,
    run_filter,
)
from mocapkit.cli.common import EXIT_OK, print_json
from mocapkit.errors import ConfigError

if TYPE_CHECKING:
    from mocapkit.body.sensor_tree import SensorTree

log = logging.getLogger("mocapkit.body")


def _parse_map(items: list[str]) -> dict[str, str]:
    out = {}
    for item in items:
        if "=" not in item:
            raise ConfigError(f"--map: expected SEGMENT=SENSOR, got {item!r}")
        seg, sensor = item.split("=", 1)
        out[seg.strip()] = sensor.strip()
    return out


def _cmd_presets(args: argparse.Namespace) -> int:
    from mocapkit.body.sensor_tree import SensorTree

    info: dict[str, dict[str, Any]] = {}
    for name in SensorTree.preset_names():
        tree = SensorTree.preset(name)
        info[name] = {
            "sensors": len(tree.segments),
            "segments": {s.name: s.sensor for s in tree.segments},
            "coordinates": list(tree.coordinate_names),
            "description": tree.description,
        }
    if args.json:
        print_json(info)
    else:
        for name, d in info.items():
            print(f"{name:18s} {d['sensors']:2d} sensors: {', '.join(d['segments'])}")
    return EXIT_OK


def _is_export(path: Path) -> bool:
    """An export of sensors on their own clocks: x-IMU3 or Xsens."""
    from mocapkit.imu.sensor_streams import is_sensor_export

    return is_sensor_export(path)


def _stream_raw(tree: Any, args: argparse.Namespace, options: dict[str, Any]) -> Any:
    """An x-IMU3 export into the body model, piece by piece: each sensor's raw samples
    through ``--filter`` (or, without one, its device orientations) into a file on disk,
    cropped to ``--start/--stop``, then all aligned onto one time base
    (:mod:`mocapkit.imu.sensor_spill`) and streamed through :func:`stream_body`."""
    import tempfile

    from mocapkit.body.streamed import stream_body
    from mocapkit.imu.sensor_spill import body_pieces
    from mocapkit.imu.sensor_streams import sensor_names, spill_device, spill_filtered

    # the whole path's message for a sensor the export lacks
    tree.check_sensors(sensor_names(Path(args.recording)))
    crop = (options.get("start"), options.get("stop"))  # cropped as the sensors are spilled
    options = {k: v for k, v in options.items() if k not in ("start", "stop")}
    with tempfile.TemporaryDirectory(prefix="mocapkit-body-") as tmp:
        sensors = [s.sensor for s in tree.segments]
        if args.filter:
            spills = spill_filtered(Path(args.recording), args.filter, args.mode, tmp,
                                 sensors=sensors, crop=crop)  # fmt: skip
        else:
            spills = spill_device(Path(args.recording), tmp, sensors, crop=crop)
        try:
            return stream_body(tree, args.recording, output=args.output,
                               segments_output=args.segments, pieces=body_pieces(spills),
                               **options)  # fmt: skip
        finally:
            for s in spills:
                s.close()


def _cmd_angles(args: argparse.Namespace) -> int:
    from mocapkit.body.calibration import BodyCalibration, HeadingFixed, HeadingFromSensor
    from mocapkit.body.pipeline import default_heading_alignment, run_body, summary
    from mocapkit.body.sensor_tree import SensorTree

    tree = SensorTree.from_yaml(args.tree) if args.tree else SensorTree.preset(args.preset)
    if args.map_file:
        mapping = json.loads(Path(args.map_file).read_text())
        if not isinstance(mapping, dict):
            raise ConfigError(f"{args.map_file}: expected a JSON object {{segment: sensor}}")
        tree = tree.with_sensor_names({str(k): str(v) for k, v in mapping.items()})
    if args.map:
        tree = tree.with_sensor_names(_parse_map(args.map))
    fmt = recording_format(Path(args.recording), args.format)
    alignment = args.heading_alignment or default_heading_alignment(args.filter, args.mode)
    # an orientation table goes through in pieces (flat memory for an hour); the BVH and
    # the joint-heading pass need the whole recording
    streamed = (
        not args.filter and fmt == "opensense-sto" and not args.bvh
        and (alignment != "joints" or bool(args.calibration_in))
    )  # fmt: skip
    # raw samples of an x-IMU3 export (sensors on their own clocks) through a filter, when
    # nothing needs the whole recording: filtered, aligned and turned into angles in pieces
    # (without --filter: the devices' own orientations, in the same pieces)
    raw_streamed = (
        _is_export(Path(args.recording)) and not args.bvh
        and (alignment != "joints" or bool(args.calibration_in))
    )  # fmt: skip
    streamed = streamed or raw_streamed
    raw = None
    orientations: Any = None
    if args.filter and not raw_streamed:  # raw samples through our filter (the joints' acc)
        raw = read_raw(Path(args.recording), fmt)
        orientations = run_filter(raw, args.filter, args.mode)
    elif not streamed:
        orientations = load_orientations(Path(args.recording), args.format)
    placement = load_orientations(Path(args.placement), args.format) if args.placement else None
    heading: HeadingFixed | HeadingFromSensor | None = None
    if args.heading_sensor:
        heading = HeadingFromSensor(args.heading_sensor, args.heading_axis)
    elif args.heading_deg is not None:
        import math

        heading = HeadingFixed(math.radians(args.heading_deg))
    calibration: Any = args.calibration
    kwargs: dict[str, Any] = {}
    joint_info = None
    if args.calibration_in:
        calibration = BodyCalibration.from_dict(json.loads(Path(args.calibration_in).read_text()))
    else:
        if alignment == "joints":
            # aligned at the held pose, kept aligned by the joints
            orientations, joint_info = _joint_headings(tree, orientations, raw)
        kwargs = {
            "heading": heading,
            "heading_alignment": alignment,
            "root_reference": args.root_reference,
        }
    options: dict[str, Any] = {
        "calibration": calibration,
        "placement": placement,
        "window": tuple(args.calib_window) if args.calib_window else None,
        "start": args.start,
        "stop": args.stop,
        "dropout": args.dropout,
        "max_hold_s": args.max_hold_s,
        **kwargs,
    }
    t0 = time.perf_counter()
    outputs = {}
    if raw_streamed:
        done = _stream_raw(tree, args, options)
    elif streamed:
        from mocapkit.body.streamed import stream_body

        done = stream_body(tree, args.recording, output=args.output,
                           segments_output=args.segments, **options)  # fmt: skip
    if streamed:
        report, cal = done.summary, done.calibration
        outputs.update({"mot": args.output} if args.output else {})
        outputs.update({"segments": args.segments} if args.segments else {})
    else:
        result = run_body(tree, orientations, **options)
        report, cal = summary(result), result.calibration
        if args.output:
            from mocapkit.io.joint_angles_mot import write_joint_angles_mot

            outputs["mot"] = str(write_joint_angles_mot(args.output, result.body.angles))
        if args.bvh:
            from mocapkit.body.skeleton import bvh_from_segments
            from mocapkit.io.bvh import write_bvh

            motion = bvh_from_segments(
                tree, result.segments, result.calibration.q_world_ground,
                bone_names=_parse_map(args.bone) if args.bone else None,
            )  # fmt: skip
            outputs["bvh"] = str(write_bvh(args.bvh, motion))
        if args.segments:
            from mocapkit.io.opensense import write_orientations_sto

            outputs["segments"] = str(write_orientations_sto(args.segments, result.segments))
    elapsed = time.perf_counter() - t0
    if args.calibration_out:
        Path(args.calibration_out).write_text(json.dumps(cal.to_dict(), indent=2))
        outputs["calibration"] = args.calibration_out
    report.update({"tree": tree.name, "outputs": outputs, "seconds": elapsed, "streamed": streamed})
    if joint_info is not None:
        import numpy as np

        report["joint_headings"] = {
            "pairs": [
                {
                    "parent": pr.parent,
                    "child": pr.child,
                    "windows_used": pr.windows,
                    "windows": pr.windows_total,
                    "drift_corrected_deg": round(float(np.degrees(np.ptp(pr.delta))), 2),
                }
                for pr in joint_info.pairs
            ],
            "notes": joint_info.notes,
        }
    if args.json:
        print_json(report)
    else:
        cal = report["calibration"]
        print(
            f"{tree.name}: {report['n_frames']} frames at {report['rate_hz']:.1f} Hz, "
            f"calibration {cal['method']} (heading {cal['heading_deg']:.1f} deg) "
            f"in {elapsed:.2f} s",
            file=sys.stderr,
        )
        for name, c in report["coordinates"].items():
            if c["min_deg"] is None:
                print(f"  {name:20s} no data")
            else:
                miss = f"  ({c['missing']} missing)" if c["missing"] else ""
                print(f"  {name:20s} {c['min_deg']:8.1f} .. {c['max_deg']:8.1f} deg{miss}")
    return EXIT_OK


_EXAMPLES = """\
examples:
  mocapkit body presets
  mocapkit body angles ../shared/data/full-body-15-imu/full_body_example_data.mat \\
      --preset full_body_15 -o angles.mot --bvh body.bvh --json
  mocapkit body angles ../shared/data/opensense/walking_orientations.sto --preset opensense \\
      -o walk.mot
"""


def register(subparsers: Any) -> None:
    raw = argparse.RawDescriptionHelpFormatter
    p = subparsers.add_parser(
        "body",
        help="sensor orientations -> body joint angles",
        epilog=_EXAMPLES,
        formatter_class=raw,
    )
    sub = p.add_subparsers(dest="body_command", metavar="SUBCOMMAND")
    pr = sub.add_parser(
        "presets",
        help="list the built-in sensor trees",
        epilog="example: mocapkit body presets --json",
        formatter_class=raw,
    )
    pr.add_argument("--json", action="store_true", help="one JSON object on stdout")
    pr.set_defaults(func=_cmd_presets)

    a = sub.add_parser(
        "angles",
        help="calibrate and compute joint angles from a recording",
        description="Recording formats: qmt full-body .mat (sensor quaternions), OpenSense "
        "quaternion .sto, x-IMU3 export directories and Xsens exports (device orientations; "
        "or --filter on the raw samples). Writes OpenSim .mot (degrees), BVH, segment "
        "orientations (.sto).",
        epilog=_EXAMPLES,
        formatter_class=raw,
    )
    a.add_argument("recording", help="recording file")
    a.add_argument(
        "--format",
        choices=FORMATS,
        default="auto",
        help="device: an x-IMU3 export directory or Xsens exports (their own orientations)",
    )
    a.add_argument(
        "--filter",
        help="run this mocapkit orientation filter (miller, bachmann) on the raw samples "
        "instead of using the recording's own orientations",
    )
    a.add_argument("--mode", choices=("9d", "6d"), default="9d", help="with --filter")
    tree = a.add_mutually_exclusive_group()
    tree.add_argument("--preset", default="full_body_15", help="built-in tree (see 'body presets')")
    tree.add_argument("--tree", help="sensor tree YAML file")
    a.add_argument("--map", action="append", metavar="SEGMENT=SENSOR", help="rename a sensor")
    a.add_argument(
        "--calibration",
        default="auto",
        choices=("auto", "npose", "tpose", "anatomical", "connectors_up"),
        help="auto: mountings and heading from a still window and the motion",
    )
    a.add_argument(
        "--calib-window",
        nargs=2,
        type=float,
        metavar=("T0", "T1"),
        help="start and end [s] of the held calibration pose (default: found from the motion)",
    )
    a.add_argument("--placement", help="separate calibration recording (OpenSense placement .sto)")
    a.add_argument("--heading-sensor", help="sensor whose --heading-axis points forward")
    a.add_argument("--heading-axis", default="x", help="x, y, z, -x, -y or -z")
    a.add_argument(
        "--heading-deg", type=float, help="body heading at calibration [deg from world x]"
    )
    a.add_argument(
        "--heading-alignment",
        choices=("hinges", "shared", "pose", "joints"),
        default=None,
        help="how the sensors' headings are aligned: hinges (one world heading, 9D or device "
        "orientations: knees, elbows and ankles compared across the joint, each segment "
        "then aligned at the held pose), shared (one world heading, each segment headed by "
        "its own functional axis), pose (each sensor's own heading, aligned at the held "
        "pose) or joints (aligned at the pose and kept aligned by the joints' "
        "accelerations: 6D drift taken out; needs --filter); default joints with --filter "
        "... --mode 6d, else hinges",
    )
    a.add_argument(
        "--root-reference",
        choices=("body", "world"),
        default="body",
        help="what the root segment's orientation is measured against",
    )
    a.add_argument(
        "--dropout",
        choices=("nan", "hold"),
        default="nan",
        help="a sensor missing from a frame: nan (its joints unknown) or hold its last orientation",
    )
    a.add_argument(
        "--max-hold-s",
        type=float,
        default=0.5,
        help="with --dropout hold: how long a missing sensor is held [s]",
    )
    a.add_argument("--start", type=float, help="ignore samples before this time [s]")
    a.add_argument(
        "--end", "--stop", dest="stop", type=float, help="ignore samples after this time [s]"
    )
    a.add_argument("-o", "--output", help="joint angles .mot")
    a.add_argument("--bvh", help="BVH file of the segment orientations")
    a.add_argument("--bone", action="append", metavar="SEGMENT=BONE", help="BVH bone name")
    a.add_argument("--segments", help="segment orientations .sto (quaternions)")
    a.add_argument("--calibration-out", help="write the calibration (JSON)")
    a.add_argument("--calibration-in", help="use a saved calibration (JSON)")
    a.add_argument("--json", action="store_true", help="one JSON object on stdout")
    a.add_argument("--map-file", help="JSON {segment: sensor}, as written by 'body identify -o'")
    a.set_defaults(func=_cmd_angles)

    from mocapkit.cli.body_identify_cmd import register as register_identify

    register_identify(sub)


def _joint_headings(
    tree: SensorTree, orientations: dict[str, Any], raw: dict[str, Any] | None
) -> tuple[dict[str, Any], Any]:
    """6D headings kept consistent through the joints (body.joint_headings)."""
    from mocapkit.body.joint_headings import align_headings_by_joints

    if raw is None:
        raise ConfigError(
            "--heading-alignment joints needs the raw samples (their accelerometers): give "
            "--filter NAME --mode 6d on a raw recording, or use --heading-alignment pose"
        )
    turned, info = align_headings_by_joints(tree, orientations, raw)
    for note in info.notes:
        warnings.warn(f"joint headings: {note}", stacklevel=2)
    return turned, info
