"""``mocapkit demo``: the orientation pipeline on the bundled real recording (a 30 s
crop of BROAD trial 07), with its figures. Works without ../shared."""

from __future__ import annotations

import argparse
import sys
from typing import Any

import numpy as np

from mocapkit.cli.common import EXIT_OK, print_json


def register(sub: Any) -> None:
    demo = sub.add_parser(
        "demo",
        help="run the orientation filters on a bundled real recording and print the errors",
        description="Runs every registered orientation filter, in 9D and 6D, on a 30 s crop "
        "of BROAD trial 07 (fast rotations; Laidig et al. 2021, CC BY 4.0) shipped with "
        "mocapkit, and prints BROAD's errors against the optical reference.",
    )
    demo.add_argument("--json", action="store_true", help="print one JSON object")
    demo.set_defaults(func=_demo)


def _demo(args: argparse.Namespace) -> int:
    from mocapkit.imu.calibration import calibrate_from_rest
    from mocapkit.imu.evaluation import evaluate
    from mocapkit.imu.filters import available_filters
    from mocapkit.io.broad import bundled_demo_trial

    trial = bundled_demo_trial()
    cal = calibrate_from_rest(trial.imu)
    rows = []
    for name in available_filters():
        for mode in ("9d", "6d"):
            result = evaluate([trial], name, mode)
            rows.append(
                {
                    "filter": name,
                    "mode": mode,
                    **result.trials[0].errors.as_degrees(),
                    "samples_per_s": result.samples_per_s,
                }
            )
    summary = {
        "recording": trial.name,
        "duration_s": trial.imu.duration,
        "rate_hz": trial.rate_hz,
        "rest_period_s": cal.period.n_samples / trial.rate_hz,
        "gyr_bias_deg_s": np.degrees(cal.gyr_bias).tolist(),
        "dip_deg": float(np.degrees(cal.references.dip)),
        "results": rows,
    }
    if args.json:
        print_json(summary)
        return EXIT_OK
    out = sys.stdout
    out.write("mocapkit demo: inertial orientation on a bundled real recording\n")
    out.write(
        f"recording: {trial.name}, {trial.imu.duration:.1f} s at {trial.rate_hz:.1f} Hz "
        f"({trial.imu.n_samples} samples); BROAD, Laidig et al. 2021, CC BY 4.0\n"
    )
    bias = ", ".join(f"{b:+.3f}" for b in np.degrees(cal.gyr_bias))
    out.write(
        f"rest calibration ({summary['rest_period_s']:.1f} s at rest): gyroscope bias "
        f"[{bias}] deg/s, magnetic dip {summary['dip_deg']:.1f} deg\n\n"
    )
    out.write("errors against the optical reference, RMS over the movement [deg]\n")
    out.write("(6D: heading-aligned total, since the heading is unobservable)\n")
    header = ("filter", "mode", "total", "heading", "incl.", "samples/s")
    out.write("{:10s} {:4s} {:>7s} {:>8s} {:>7s} {:>11s}\n".format(*header))
    for r in rows:
        out.write(
            f"{r['filter']:10s} {r['mode']:4s} {r['total_deg']:7.2f} {r['heading_deg']:8.2f} "
            f"{r['inclination_deg']:7.2f} {r['samples_per_s']:11,.0f}\n"
        )
    out.write("\nall 8 BROAD trials: mocapkit imu evaluate ../shared/data/broad --filter NAME\n")
    return EXIT_OK
