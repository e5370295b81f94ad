"""Demo section: every orientation filter, 9D and 6D, on the bundled real BROAD crop."""

from __future__ import annotations

from typing import Any, Literal

import numpy as np

from mocapkit.demo.progress import Progress, no_progress
from mocapkit.viz.plots import imu_errors_figure
from mocapkit.viz.report import HtmlReport


def run_imu(progress: Progress = no_progress) -> dict[str, Any]:
    """Errors against the optical reference (BROAD's metric) and throughput per filter.

    Returns the figures (``recording``, ``duration_s``, ``rate_hz``, ``rest_period_s``,
    ``gyr_bias_deg_s``, ``dip_deg``, ``results``: one row per filter and mode).
    """
    from mocapkit.imu.calibration import calibrate_from_rest
    from mocapkit.imu.evaluation import evaluate
    from mocapkit.imu.filters import available_filters
    from mocapkit.io.broad import bundled_demo_trial

    trial = bundled_demo_trial()
    cal = calibrate_from_rest(trial.imu)
    modes: tuple[Literal["9d", "6d"], ...] = ("9d", "6d")
    runs = [(name, mode) for name in available_filters() for mode in modes]
    rows = []
    for i, (name, mode) in enumerate(runs):
        progress("orientation filters", i, len(runs))
        result = evaluate([trial], name, mode)
        rows.append(
            {
                "filter": name,
                "mode": mode,
                **result.trials[0].errors.as_degrees(),
                "samples_per_s": result.samples_per_s,
            }
        )
    progress("orientation filters", len(runs), len(runs))
    return {
        "recording": trial.name,
        "duration_s": trial.imu.duration,
        "rate_hz": trial.rate_hz,
        "rest_period_s": cal.period.n_samples / trial.rate_hz,
        "gyr_bias_deg_s": np.degrees(cal.gyr_bias).tolist(),
        "dip_deg": float(np.degrees(cal.references.dip)),
        "results": rows,
    }


def report_imu(report: HtmlReport, imu: dict[str, Any]) -> None:
    sec = report.section(
        "Orientation filters on a real recording",
        f"BROAD trial {imu['recording']} (Laidig et al. 2021, CC BY 4.0), "
        f"{imu['duration_s']:.0f} s at {imu['rate_hz']:.1f} Hz, bundled with mocapkit. "
        "Errors against the optical reference, RMS over the movement; in 6D the heading is "
        "unobservable, so the total is heading-aligned.",
    )
    bias = ", ".join(f"{b:+.3f}" for b in imu["gyr_bias_deg_s"])
    sec.table(
        ["rest calibration", "value"],
        [
            ["rest period [s]", imu["rest_period_s"]],
            ["gyroscope bias [deg/s]", bias],
            ["magnetic dip [deg]", imu["dip_deg"]],
        ],
    )
    sec.table(
        ["filter", "mode", "total [deg]", "heading [deg]", "inclination [deg]", "samples/s"],
        [
            [r["filter"], r["mode"], r["total_deg"], r["heading_deg"], r["inclination_deg"],
             f"{r['samples_per_s']:,.0f}"]
            for r in imu["results"]
        ],
    )  # fmt: skip
    sec.figure(imu_errors_figure(imu["results"], "Filter errors (BROAD crop)"), "Filter errors")
    sec.note("All 8 BROAD trials: mocapkit imu evaluate ../shared/data/broad --filter NAME")
