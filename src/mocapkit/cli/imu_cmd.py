"""``mocapkit imu``: evaluate filters on BROAD, run a filter on a recording, calibrate
a magnetometer. Parsing and printing only; the work is in ``mocapkit.imu``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.cli.common import EXIT_OK, print_json, progress
from mocapkit.errors import ConfigError, DataError

DEVICE = "device"


def _param(text: str) -> tuple[str, float]:
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    try:
        return key.strip(), float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{key}: {value!r} is not a number") from None


def _filter_names() -> list[str]:
    from mocapkit.imu.filter_names import BUILTIN_FILTERS

    return list(BUILTIN_FILTERS)


_EXAMPLES = """\
examples:
  mocapkit imu evaluate ../shared/data/broad --filter miller --mode 9d --json
  mocapkit imu run ../shared/data/ximu3-lower-body --filter bachmann -o lower_body.sto
  mocapkit imu calibrate-mag recording.csv --json
"""


def register(sub: Any) -> None:
    raw = argparse.RawDescriptionHelpFormatter
    imu = sub.add_parser(
        "imu",
        help="inertial orientation: evaluate, run, calibrate",
        epilog=_EXAMPLES,
        formatter_class=raw,
    )
    cmds = imu.add_subparsers(dest="imu_command", metavar="SUBCOMMAND")
    names = _filter_names()

    ev = cmds.add_parser(
        "evaluate",
        help="run a filter on every BROAD trial in DIR and print BROAD's errors",
        description="Errors in degrees: RMS over the movement phases (BROAD's metric). In "
        "6D the heading is unobservable: one constant heading offset is removed first, so "
        "total_deg is the heading-aligned total. samples_per_s is the single-thread "
        "throughput of the chosen backend (the numba fast path by default), compilation "
        "excluded.",
        epilog="examples:\n  mocapkit imu evaluate ../shared/data/broad --filter miller --json\n"
        "  mocapkit imu evaluate ../shared/data/broad --filter bachmann --mode 6d",
        formatter_class=raw,
    )
    ev.add_argument("directory", type=Path, help="directory of BROAD .hdf5 trials")
    ev.add_argument(
        "--filter", required=True, choices=names, dest="filter_name", help="orientation filter"
    )
    ev.add_argument(
        "--backend",
        choices=["fast", "reference"],
        default="fast",
        help="fast (numba, default) or reference (readable numpy)",
    )
    _filter_options(ev, "each trial")
    ev.add_argument("--json", action="store_true", help="print one JSON object")
    ev.set_defaults(func=_evaluate)

    run = cmds.add_parser(
        "run",
        help="orientation of a recording -> OpenSense-style quaternion .sto",
        description="Reads a BROAD .hdf5, a mocapkit .csv, an x-IMU3 export (one sensor "
        "or a directory of sensors) or Xsens exports. Sensors with their own clocks are "
        "put on one uniform time base (slerp, never extrapolated) for the table. "
        "'--filter device' writes the orientation the device computed itself.",
        epilog="examples:\n  mocapkit imu run ../shared/data/ximu3-lower-body --filter miller "
        "-o lower_body.sto\n  mocapkit imu run ../shared/data/ximu3-lower-body --filter device "
        "-o device.sto",
        formatter_class=raw,
    )
    run.add_argument(
        "path",
        type=Path,
        help="a recording: mocapkit CSV, BROAD .hdf5, x-IMU3 or Xsens export (file or directory)",
    )
    run.add_argument(
        "--filter",
        required=True,
        choices=[*names, DEVICE],
        dest="filter_name",
        help="orientation filter",
    )
    run.add_argument(
        "-o",
        "--output",
        type=Path,
        required=True,
        help="output: .sto or .mot (OpenSense quaternion table) or .csv (time_s, <sensor>_w..z)",
    )
    run.add_argument("--sensor", action="append", default=[], help="only this sensor")
    _filter_options(run, "the recording")
    run.add_argument("--json", action="store_true", help="print one JSON summary on stdout")
    run.set_defaults(func=_run)

    cal = cmds.add_parser(
        "calibrate-mag",
        help="hard- and soft-iron magnetometer calibration (ellipsoid fit)",
        description="Fit the magnetometer readings of a rotation sequence. With -o the "
        "calibrated recording of one sensor is written as a mocapkit CSV.",
        epilog="examples:\n  mocapkit imu calibrate-mag recording.csv --json\n"
        "  mocapkit imu calibrate-mag export_dir --sensor 'Left Foot' -o left_foot_cal.csv",
        formatter_class=raw,
    )
    cal.add_argument(
        "path",
        type=Path,
        help="a recording: mocapkit CSV, BROAD .hdf5, x-IMU3 or Xsens export (file or directory)",
    )
    cal.add_argument("--sensor", action="append", default=[], help="only this sensor (repeatable)")
    cal.add_argument(
        "--model",
        choices=["ellipsoid", "sphere"],
        default="ellipsoid",
        help="ellipsoid (hard and soft iron, default) or sphere (hard iron only)",
    )
    cal.add_argument(
        "--field-strength",
        type=float,
        default=None,
        help="the local field's magnitude in the readings' unit (default: fitted)",
    )
    cal.add_argument("-o", "--output", type=Path, default=None, help="calibrated .csv")
    cal.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    cal.set_defaults(func=_calibrate_mag)

    rl = cmds.add_parser(
        "record-lsl",
        help="record an LSL IMU stream (gyroscope rad/s, accelerometer m/s^2[, magnetometer])",
        description="Resolve the Lab Streaming Layer stream NAME, record it for --seconds with "
        "its own timestamps and write a mocapkit IMU CSV (6 or 9 channels: gyroscope, "
        "accelerometer, magnetometer, in that order).",
        epilog="examples:\n  mocapkit imu record-lsl --stream MyIMU --seconds 30 -o imu.csv --json",
        formatter_class=raw,
    )
    rl.add_argument("--stream", required=True, help="the LSL stream's name")
    rl.add_argument("--seconds", type=float, default=10.0, help="how long to record [s]")
    rl.add_argument("-o", "--output", type=Path, required=True, help="mocapkit IMU .csv")
    rl.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    rl.set_defaults(func=_record_lsl)


def _filter_options(p: Any, what: str) -> None:
    """The options of how a filter runs, shared by ``evaluate`` and ``run``."""
    p.add_argument(
        "--mode",
        choices=["9d", "6d"],
        default="9d",
        help="9d (with the magnetometer, default) or 6d",
    )
    p.add_argument(
        "--param",
        type=_param,
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a filter parameter, e.g. tau_acc=2.0 (repeatable)",
    )
    p.add_argument(
        "--remove-gyr-bias",
        action="store_true",
        help=f"subtract the gyroscope bias measured over {what}'s first rest period",
    )
    p.add_argument(
        "--offline",
        action="store_true",
        help=f"the filter's offline mode (forward-backward over {what}; polaris)",
    )


def _bias_remover(enabled: bool) -> Any:
    if not enabled:
        return None
    from mocapkit.imu.calibration import calibrate_from_rest, remove_gyro_bias

    def prepare(trial: Any) -> Any:
        imu = trial.imu if hasattr(trial, "imu") else trial
        return remove_gyro_bias(imu, calibrate_from_rest(imu, use_mag=False).gyr_bias)

    return prepare


def _evaluate(args: argparse.Namespace) -> int:
    from mocapkit.imu.evaluation import evaluate
    from mocapkit.io.broad import list_broad_trials, read_broad_trial

    paths = list_broad_trials(args.directory)
    trials = (
        read_broad_trial(p)
        for p in progress(paths, f"{args.filter_name} {args.mode}", total=len(paths))
    )
    result = evaluate(
        trials,
        args.filter_name,
        args.mode,
        args.backend,
        prepare=_bias_remover(args.remove_gyr_bias),
        offline=args.offline,
        **dict(args.param),
    )
    if args.json:
        print_json(result.as_json())
        return EXIT_OK
    out = sys.stdout
    aligned = " (heading-aligned total)" if args.mode == "6d" else ""
    how = "offline" if args.offline else "online"
    out.write(f"filter {args.filter_name} ({how}), {args.mode}{aligned}, backend {args.backend}\n")
    out.write(f"{'trial':40s} {'total':>8s} {'heading':>8s} {'incl.':>8s}  [deg]\n")
    for t in result.trials:
        d = t.errors.as_degrees()
        out.write(
            f"{t.name:40s} {d['total_deg']:8.3f} {d['heading_deg']:8.3f} "
            f"{d['inclination_deg']:8.3f}\n"
        )
    out.write(
        f"{'mean':40s} {result.mean_deg('total'):8.3f} {result.mean_deg('heading'):8.3f} "
        f"{result.mean_deg('inclination'):8.3f}\n"
    )
    out.write(f"throughput: {result.samples_per_s:,.0f} samples/s (single thread)\n")
    return EXIT_OK


def _run(args: argparse.Namespace) -> int:
    from mocapkit.imu.evaluation import check_offline
    from mocapkit.imu.filters import make_filter
    from mocapkit.imu.filters.base import recording_steps
    from mocapkit.imu.resample import common_time_base, resample_orientation
    from mocapkit.imu.sensor_streams import select_sensors
    from mocapkit.io.imu_files import read_device_orientations, read_imu_recordings
    from mocapkit.io.opensim_table import write_table
    from mocapkit.series import OrientationSeries

    if args.output.suffix.lower() not in (".sto", ".mot", ".csv"):
        raise ConfigError(
            f"-o {args.output}: the output format follows the extension: .sto or .mot "
            "(OpenSense quaternion table) or .csv"
        )
    if _streams(args):
        return _run_streamed(args)
    series: dict[str, OrientationSeries] = {}
    if args.filter_name == DEVICE:
        series = select_sensors(read_device_orientations(args.path), args.sensor, args.path)
    else:
        recs = select_sensors(read_imu_recordings(args.path), args.sensor, args.path)
        prepare = _bias_remover(args.remove_gyr_bias)
        for name, rec in progress(list(recs.items()), args.filter_name, total=len(recs)):
            rec = prepare(rec) if prepare else rec
            filt = make_filter(args.filter_name, rec.rate_hz, **dict(args.param))
            if args.offline:
                mag = rec.mag if args.mode == "9d" else None
                q = check_offline(filt, args.filter_name).run_offline(
                    rec.gyr, rec.acc, mag, dt=recording_steps(rec, filt.params.dt)
                )
                series[name] = OrientationSeries(rec.time, q, name=rec.name)
                continue
            series[name] = filt.run_recording(rec, use_mag=args.mode == "9d")
            report = filt.last_report
            if report.mag_gaps or report.acc_rejected or report.mag_rejected:
                print(
                    f"{name}: {report.mag_gaps} magnetometer gaps and "
                    f"{report.mag_rejected} rejected samples processed as 6D, "
                    f"{report.acc_rejected} accelerometer samples rejected",
                    file=sys.stderr,
                )
    items = list(series.values())
    if len(items) == 1:
        time, quats = items[0].time, items[0].quat[:, None, :]
    else:
        time = common_time_base(items)
        quats = np.stack([resample_orientation(s, time) for s in items], axis=1)
        print(
            f"resampled {len(items)} sensors onto one time base ({len(time)} samples, "
            f"{time[0]:.3f}..{time[-1]:.3f} s) by slerp",
            file=sys.stderr,
        )
    labels = ["_".join(name.split()) for name in series]
    if args.output.suffix.lower() == ".csv":
        _write_quat_csv(args.output, time - time[0], labels, quats)
    else:
        write_table(args.output, time - time[0], labels, quats, name=args.path.stem)
    print(f"wrote {args.output} ({len(time)} rows, sensors: {', '.join(labels)})", file=sys.stderr)
    if args.json:
        print_json(
            {"output": str(args.output), "rows": len(time), "sensors": labels,
             "filter": args.filter_name, "mode": args.mode, "offline": args.offline}
        )  # fmt: skip
    return EXIT_OK


def _streams(args: argparse.Namespace) -> bool:
    """Read, filtered and written piece by piece: one mocapkit IMU CSV or BROAD .hdf5
    trial (online, or smoothed offline through files on disk), or an x-IMU3 or Xsens
    export (every sensor on its own clock through files on disk, filtered online or
    smoothed, or its device orientations, then resampled onto one time base)."""
    from mocapkit.imu.sensor_streams import is_sensor_export

    path = Path(args.path)
    if path.is_file():
        return (args.filter_name != DEVICE and path.suffix.lower() in (".csv", ".hdf5", ".h5")
                and not args.sensor)  # fmt: skip
    return is_sensor_export(path)


def _run_streamed(args: argparse.Namespace) -> int:
    from mocapkit.imu.sensor_streams import run_sensors_streaming
    from mocapkit.imu.streaming import run_file_offline, run_file_streaming

    path = Path(args.path)
    if path.is_dir():
        rep = run_sensors_streaming(path, args.filter_name, args.output, mode=args.mode,
                                  params=dict(args.param), sensors=args.sensor or None,
                                  remove_gyr_bias=args.remove_gyr_bias,
                                  offline=args.offline)  # fmt: skip
        for note in rep.notes:
            print(note, file=sys.stderr)
        labels = ["_".join(n.split()) for n in rep.sensors]
    else:
        run = run_file_offline if args.offline else run_file_streaming
        rep = run(path, args.filter_name, args.output, mode=args.mode,
                  params=dict(args.param), remove_gyr_bias=args.remove_gyr_bias)  # fmt: skip
        if rep.mag_gaps or rep.acc_rejected or rep.mag_rejected:
            print(
                f"{rep.sensor}: {rep.mag_gaps} magnetometer gaps and {rep.mag_rejected} "
                f"rejected samples processed as 6D, {rep.acc_rejected} accelerometer samples "
                "rejected",
                file=sys.stderr,
            )
        labels = ["_".join(rep.sensor.split())]
    print(f"wrote {args.output} ({rep.rows} rows, sensors: {', '.join(labels)})",
          file=sys.stderr)  # fmt: skip
    if args.json:
        print_json(
            {"output": str(args.output), "rows": rep.rows, "sensors": labels,
             "filter": args.filter_name, "mode": args.mode, "offline": args.offline,
             "streamed": True, "chunks": rep.chunks}
        )  # fmt: skip
    return EXIT_OK


def _write_quat_csv(path: Path, time: Any, labels: list[str], quats: Any) -> None:
    """A plain CSV: ``time_s`` then ``<sensor>_w, _x, _y, _z`` per sensor (q_world_sensor)."""
    from mocapkit.io.opensim_table import QuaternionTableWriter

    with QuaternionTableWriter(path, labels, 0.0, "", csv=True) as w:
        w.write(np.asarray(time, dtype=float), np.asarray(quats, dtype=float))


def _calibrate_mag(args: argparse.Namespace) -> int:
    from mocapkit.imu.mag_calibration import fit_mag_calibration
    from mocapkit.imu.sensor_streams import select_sensors
    from mocapkit.io.imu_csv import write_imu_csv
    from mocapkit.io.imu_files import read_imu_recordings
    from mocapkit.series import ImuRecording

    recs = select_sensors(read_imu_recordings(args.path), args.sensor, args.path)
    if args.output is not None and len(recs) != 1:
        raise ConfigError(
            f"-o: {len(recs)} sensors in {args.path}; choose one with --sensor to write it"
        )
    results = {}
    for name, rec in recs.items():
        if rec.mag is None:
            raise DataError(f"{name}: this recording has no magnetometer to calibrate")
        cal = fit_mag_calibration(rec.mag, model=args.model, field_strength=args.field_strength)
        raw = np.linalg.norm(rec.mag[rec.mag_valid], axis=1)
        fixed = np.linalg.norm(cal.apply(rec.mag[rec.mag_valid]), axis=1)
        results[name] = {
            **cal.as_dict(),
            "raw_norm_std": float(np.std(raw)),
            "calibrated_norm_std": float(np.std(fixed)),
        }
        if args.output is not None:
            meta = dict(rec.meta)
            meta["mag_calibration"] = cal.as_dict()
            out = ImuRecording(
                rec.time, rec.gyr, rec.acc, cal.apply(rec.mag), name=rec.name, meta=meta
            )
            write_imu_csv(args.output, out)
            print(f"wrote {args.output}", file=sys.stderr)
    if args.json:
        print_json({"sensors": results})
        return EXIT_OK
    for name, r in results.items():
        print(f"{name}: {r['model']} fit on {r['n_samples']} samples")
        print(f"  hard iron: {np.array2string(np.asarray(r['hard_iron']), precision=4)}")
        soft = np.array2string(np.asarray(r["soft_iron"]), precision=4, prefix="  soft iron: ")
        print(f"  soft iron: {soft}")
        print(
            f"  field norm std: {r['raw_norm_std']:.4g} raw -> {r['calibrated_norm_std']:.4g} "
            f"calibrated (field strength {r['field_strength']:.4g})"
        )
    return EXIT_OK


def _record_lsl(args: Any) -> int:
    from mocapkit.io.imu_csv import write_imu_csv
    from mocapkit.io.lsl import record_imu

    if not args.seconds > 0:
        raise ConfigError(f"--seconds: expected a positive duration, got {args.seconds}")
    if args.output.suffix.lower() != ".csv":
        raise ConfigError(f"-o {args.output}: the recording is written as a mocapkit .csv")
    rec = record_imu(args.stream, args.seconds)
    path = write_imu_csv(args.output, rec)
    summary = {"stream": args.stream, "samples": rec.n_samples, "rate_hz": rec.rate_hz,
               "magnetometer": rec.has_mag, "output": str(path)}  # fmt: skip
    if args.json:
        print_json(summary)
    else:
        print(f"{args.stream}: {rec.n_samples} samples at {rec.rate_hz:.1f} Hz -> {path}")
    return EXIT_OK
