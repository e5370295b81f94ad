"""``mocapkit markers``: reconstruct joint angles from optical markers, draw the paper's
figures, inspect a marker file. Parsing and printing only; the work is in mocapkit.markers."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path
from typing import Any

from mocapkit.cli.common import EXIT_OK, StepProgress, print_json, process_seconds
from mocapkit.errors import ConfigError

log = logging.getLogger(__name__)


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("trial", type=Path, help="marker trial (.c3d or .trc)")
    p.add_argument(
        "--static",
        type=Path,
        default=None,
        help="static (standing) trial for scaling and marker registration; without "
        "it the limb lengths are estimated from the trial itself",
    )
    p.add_argument(
        "--method",
        choices=("osc", "ik"),
        default="osc",
        help="osc: direct marker control (default); ik: least-squares IK baseline",
    )
    p.add_argument(
        "--mode",
        choices=("offline", "online"),
        default="offline",
        help="offline: whole trial in one compiled run; online: frame by frame",
    )
    p.add_argument(
        "--markerset",
        default=None,
        help="preset name (gait2392, cmu41, walking2) or YAML file; default: the "
        "preset matching most labels",
    )
    p.add_argument(
        "--grouping",
        default="single",
        help="marker priority levels for osc: single, independent, tree, weights, "
        "paper (the paper's two subsets above all other markers), paper-only (the paper's "
        "four markers alone), or a YAML file (default: single)",
    )
    p.add_argument(
        "--height-m",
        type=float,
        default=None,
        help="stature [m] (default: estimated from the static trial)",
    )
    p.add_argument("--mass-kg", type=float, default=None, help="body mass [kg] (default 75)")
    p.add_argument(
        "--sex",
        choices=("male", "female"),
        default="male",
        help="which de Leva table (default male)",
    )
    p.add_argument(
        "--units",
        choices=("auto", "mm", "cm", "m"),
        default="auto",
        help="marker units (default: as declared, checked against body size)",
    )
    p.add_argument(
        "--up-axis",
        default="auto",
        help="file's up axis: auto (from the static trial), z, y, x, -z, -y, -x",
    )
    p.add_argument(
        "--fill-gaps",
        choices=("none", "rigid", "spline", "both"),
        default="none",
        help="fill gaps up to --max-gap-s (default none)",
    )
    p.add_argument("--max-gap-s", type=float, default=0.25, help="longest gap to fill [s]")
    p.add_argument(
        "--lowpass-hz",
        type=float,
        default=None,
        help="zero-phase Butterworth low-pass cut-off [Hz] (default off)",
    )
    p.add_argument(
        "--ik-setup",
        type=Path,
        default=None,
        help="OpenSim IK setup XML (e.g. subject01_Setup_IK.xml): its marker weights, "
        "coordinate tasks and time range (--start/--end win)",
    )
    p.add_argument(
        "--start", "--start-s", dest="start_s", type=float, default=None,
        help="first time to use [s]",
    )  # fmt: skip
    p.add_argument(
        "--end", "--end-s", dest="end_s", type=float, default=None, help="last time to use [s]"
    )
    p.add_argument(
        "--substeps", type=int, default=2, help="simulation steps per frame for osc (default 2)"
    )
    p.add_argument(
        "--backend",
        choices=("fast", "reference"),
        default="fast",
        help="fast (numba) or reference (Pinocchio + numpy)",
    )
    p.add_argument(
        "--total-bound",
        action="store_true",
        help="also compute the joint-error bound that holds (distance to the markers' "
        "best fit plus 4 standard deviations of marker noise; a fit per frame). Eq. 15's "
        "bound is always computed",
    )


_GAIT = "../shared/data/opensim/gait2392"
_EX_RECONSTRUCT = f"""examples:
  mocapkit markers reconstruct {_GAIT}/subject01_walk1.trc \\
      --static {_GAIT}/subject01_static.trc --height-m 1.8034 --mass-kg 72.6 -o walk.mot --json
  mocapkit markers reconstruct {_GAIT}/subject01_walk1.trc --static {_GAIT}/subject01_static.trc \\
      --ik-setup {_GAIT}/subject01_Setup_IK.xml --method ik -o walk_ik.mot
  mocapkit markers reconstruct ../shared/data/c3d/walking2.c3d --markerset walking2 --method ik \\
      -o walking2.mot
"""
_EX_REPORT = f"""examples:
  mocapkit markers report {_GAIT}/subject01_walk1.trc --static {_GAIT}/subject01_static.trc \\
      --reference {_GAIT}/reference/OutputReference_subject01_walk1_ik.mot -o report/
  mocapkit markers report {_GAIT}/subject01_walk1.trc --grouping paper -o report_paper/
"""
_EX_INSPECT = """examples:
  mocapkit markers inspect ../shared/data/c3d/cmu_85_02.c3d
  mocapkit markers inspect walk.trc --units mm --json
"""


def register(subparsers: Any) -> None:
    raw = argparse.RawDescriptionHelpFormatter
    parser = subparsers.add_parser(
        "markers", help="optical markers: reconstruct joint angles, report, inspect",
        description="Optical marker data (C3D/TRC) to joint angles by direct marker control "
                    "(prioritized operational-space control) or least-squares IK.",
        epilog=_EX_RECONSTRUCT, formatter_class=raw,
    )  # fmt: skip
    sub = parser.add_subparsers(dest="markers_command", metavar="SUBCOMMAND")
    rec = sub.add_parser(
        "reconstruct", help="joint angles from a marker trial",
        description="Reconstruct joint angles; writes .mot (or .csv) and prints figures.",
        epilog=_EX_RECONSTRUCT, formatter_class=raw,
    )  # fmt: skip
    _add_common(rec)
    rec.add_argument(
        "-o",
        "--output",
        type=Path,
        required=True,
        help="output joint angles: .mot (OpenSim) or .csv",
    )
    rec.add_argument(
        "--save-markerset",
        type=Path,
        default=None,
        help="also save the marker set used (a preset, or the one assigned automatically "
        "to labels no preset knows) as YAML, to check, edit and pass with --markerset",
    )
    rec.add_argument(
        "--osim",
        type=Path,
        default=None,
        help="also write the scaled model (bodies, joints, registered markers) as an "
        "OpenSim .osim that the .mot poses",
    )
    rec.add_argument(
        "--tracked-trc",
        type=Path,
        default=None,
        help="also write the model's tracked markers as TRC (OpenSim's y-up ground, mm)",
    )
    rec.add_argument(
        "--tracked-c3d",
        type=Path,
        default=None,
        help="also write the model's tracked markers as C3D, in the trial's axes, with a "
        "C3D trial's analogs, force platforms and events",
    )
    rec.add_argument(
        "--json",
        action="store_true",
        help='print {"frames", "solve_fps", "marker_rms_mm", "marker_max_mm", '
        '"joint_error_bound_deg_max", "fps", "seconds"}: fps and seconds of the whole '
        "command (start to files written), solve_fps of the reconstruction loop alone",
    )
    rec.set_defaults(func=_reconstruct)
    rep = sub.add_parser(
        "report", help="the paper's Figures 2-4 for a trial",
        description="Joint angles (Fig. 2), tracked versus commanded markers (Fig. 3) and "
                    "marker / joint error margins (Fig. 4) as PNG files plus report.json.",
        epilog=_EX_REPORT, formatter_class=raw,
    )  # fmt: skip
    _add_common(rep)
    rep.add_argument("-o", "--output", type=Path, required=True, help="output directory")
    rep.add_argument(
        "--reference",
        type=Path,
        default=None,
        help="a .mot to compare joint angles with (e.g. OpenSim's IK)",
    )
    rep.add_argument(
        "--reference-model",
        choices=("auto", "gait2392", "rajagopal"),
        default="auto",
        help="whose sign conventions the reference uses (gait2392: knee flexion negative; "
        "auto: told from the knee columns); default auto",
    )
    rep.add_argument("--json", action="store_true", help="print the report's figures")
    rep.set_defaults(func=_report)
    ins = sub.add_parser(
        "inspect", help="markers, frames, units, gaps of a marker file",
        epilog=_EX_INSPECT, formatter_class=raw,
    )  # fmt: skip
    ins.add_argument("file", type=Path, help="a marker file (.c3d or .trc)")
    ins.add_argument(
        "--units",
        choices=("auto", "mm", "cm", "m"),
        default="auto",
        help="override the file's length unit (mm, cm, m)",
    )
    ins.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    ins.set_defaults(func=_inspect)
    parser.set_defaults(func=lambda a: parser.print_help() or 2)


def _options(args: argparse.Namespace) -> Any:
    from mocapkit.markers.ik import IKParams
    from mocapkit.markers.osc import OSCParams
    from mocapkit.markers.reconstruct import ReconstructionOptions

    if args.substeps < 1:
        raise ConfigError(f"--substeps: expected >= 1, got {args.substeps}")
    return ReconstructionOptions(
        method=args.method, mode=args.mode, grouping=args.grouping, units=args.units,
        up_axis=args.up_axis, fill_gaps=args.fill_gaps, max_gap_s=args.max_gap_s,
        lowpass_hz=args.lowpass_hz, start_s=args.start_s, end_s=args.end_s,
        total_bound=args.total_bound or args.func is _report,
        osc=OSCParams(substeps=args.substeps, backend=args.backend),
        ik=IKParams(backend=args.backend),
    )  # fmt: skip


def _run(args: argparse.Namespace) -> Any:
    from mocapkit.markers.reconstruct import run

    options = _options(args)
    with StepProgress() as bars:  # on stderr, when it is a terminal
        return run(
            args.trial, args.static, args.markerset, args.height_m, args.mass_kg, options,
            args.sex, args.ik_setup, progress=bars,
        )  # fmt: skip


def _reconstruct(args: argparse.Namespace) -> int:
    suffix = args.output.suffix.lower()
    if suffix not in (".mot", ".csv"):
        raise ConfigError(f"-o {args.output}: expected a .mot or .csv file name")
    from mocapkit.markers.streamed import reconstruct_streamed, streamable

    options = _options(args)
    if streamable(args.trial, options) is None:
        # piece by piece at flat memory (the same numbers; mocapkit.markers.streamed)
        with StepProgress() as bars:
            streamed = reconstruct_streamed(
                args.trial, args.static, args.markerset, args.height_m, args.mass_kg,
                options, args.output, sex=args.sex, ik_setup=args.ik_setup,
                tracked_trc=args.tracked_trc, tracked_c3d=args.tracked_c3d, progress=bars,
            )  # fmt: skip
        _side_files(args, streamed.subject)
        return _print_figures(args, streamed.metrics)
    result, subject, _ = _run(args)
    _side_files(args, subject)
    if suffix == ".mot":
        result.write_mot(args.output)
    else:
        result.write_csv(args.output)
    if args.tracked_trc is not None:
        result.write_tracked_trc(args.tracked_trc)
    if args.tracked_c3d is not None:
        result.write_tracked_c3d(args.tracked_c3d)
    return _print_figures(args, result.metrics())


def _side_files(args: argparse.Namespace, subject: Any) -> None:
    """--save-markerset and --osim."""
    if args.save_markerset is not None:
        from mocapkit.body.markersets import save_markerset

        save_markerset(subject.markerset, args.save_markerset)
    if args.osim is not None:
        from mocapkit.io.osim_model import write_osim

        write_osim(args.osim, subject.human)


def _print_figures(args: argparse.Namespace, m: dict[str, Any]) -> int:
    seconds = process_seconds()
    m["fps"] = round(m["frames"] / seconds, 1) if seconds > 0 else None
    m["seconds"] = round(seconds, 3)
    if args.json:
        print_json(m)
    else:
        print(
            f"{m['frames']} frames in {m['seconds']} s ({m['fps']} frames/s end to end, "
            f"{m['solve_fps']} in the solve); marker RMS {m['marker_rms_mm']} mm "
            f"(max {m['marker_max_mm']} mm); joint error bound max "
            f"{m['joint_error_bound_deg_max']} deg -> {args.output}"
        )
    return EXIT_OK


def _report(args: argparse.Namespace) -> int:
    from mocapkit.viz.marker_report import write_report

    result, _subject, _cleaning = _run(args)
    summary = write_report(
        result, args.output, reference=args.reference, reference_model=args.reference_model
    )
    if args.json:
        print_json(summary)
    else:
        print(f"report written to {args.output} ({', '.join(summary['figures'])})")
    return EXIT_OK


def _inspect(args: argparse.Namespace) -> int:
    import numpy as np

    from mocapkit.markers.cleaning import find_gaps
    from mocapkit.markers.conventions import body_size_m
    from mocapkit.markers.reconstruct import load_markers

    traj = load_markers(args.file, args.units)
    gaps, never = find_gaps(traj)
    info = {
        "file": str(args.file),
        "frames": traj.n_frames,
        "rate_hz": traj.rate_hz,
        "markers": list(traj.names),
        "declared_units": traj.meta.get("units"),
        "body_size_m": round(body_size_m(traj), 3) if traj.visible.any() else None,
        "visible_fraction": round(float(np.mean(traj.visible)), 3),
        "gaps": len(gaps),
        "never_visible": never,
        "dropped_unlabelled": traj.meta.get("dropped_unlabelled", []),
        "truncated": traj.meta.get("truncated"),
    }
    extras = traj.meta.get("c3d")
    if extras is not None:
        info["analog_channels"] = list(extras.analog_labels)
        info["analog_rate_hz"] = extras.analog_rate_hz
        fp = extras.groups.get("FORCE_PLATFORM", {})
        info["force_plates"] = int(np.asarray(fp.get("USED", [0])).reshape(-1)[0]) if fp else 0
        info["events"] = [
            {"label": e.label, "context": e.context, "time_s": e.time_s} for e in extras.events
        ]
    if args.json:
        print_json(info)
    else:
        for k, v in info.items():
            print(f"{k}: {v}")
    return EXIT_OK
