"""The body model on the real recordings: plausibility figures and plots.

    .venv/bin/python -m benchmarks.body_recordings [--plots docs/figures] [--json]

- qmt full-body recording (16 sensors; the full_body_15 preset uses 15, mountings and
  heading estimated automatically);
- OpenSense walking (8 IMUs, OpenSense's placement pose and base-IMU heading), plotted
  against OpenSim's IMU IK angles (tests/data/opensense_imu_ik_reference.mot);
- x-IMU3 lower body (7 sensors, their own fusion quaternions), when its reader is present.

Per recording: calibration diagnostics, per coordinate the 2nd-98th percentile range
[deg] in the gait windows, and the largest sample-to-sample step [deg] (continuity).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.body.calibration import HeadingFromSensor
from mocapkit.body.pipeline import BodyResult, run_body
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.imu.filters.base import make_filter
from mocapkit.io.imu_files import read_device_orientations, read_imu_recordings
from mocapkit.io.joint_angles_mot import read_joint_angles_mot
from mocapkit.io.opensense import read_orientations_sto
from mocapkit.io.qmt_mat import read_qmt_mat
from mocapkit.series import ImuRecording

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"
FULL_BODY_WALK = [(96.0, 114.0), (117.0, 138.0)]
KEY = (
    "knee_angle_r", "knee_angle_l", "hip_flexion_r", "hip_flexion_l", "ankle_angle_r",
    "ankle_angle_l", "pelvis_tilt", "pelvis_list", "lumbar_extension", "elbow_flex_r",
)  # fmt: skip


def plausibility(res: BodyResult, windows: list[tuple[float, float]] | None) -> dict[str, Any]:
    a = res.body.angles
    mask = np.zeros(a.n_samples, dtype=bool)
    for w0, w1 in windows or [(a.time[0], a.time[-1])]:
        mask |= (a.time >= w0) & (a.time <= w1)
    out: dict[str, Any] = {}
    for name in a.names:
        v = np.rad2deg(a.column(name))
        steps = np.abs(np.diff(v))
        out[name] = {
            "p2_deg": float(np.nanpercentile(v[mask], 2)),
            "p98_deg": float(np.nanpercentile(v[mask], 98)),
            "max_step_deg": float(np.nanmax(steps)),
            "missing": int(np.isnan(v).sum()),
        }
    return out


def full_body() -> tuple[BodyResult, float]:
    rec = read_qmt_mat(DATA / "full-body-15-imu" / "full_body_example_data.mat")
    t0 = time.perf_counter()
    res = run_body(SensorTree.preset("full_body_15"), rec.orientation, start=40.3)
    return res, time.perf_counter() - t0


def opensense() -> BodyResult:
    d = DATA / "opensense"
    return run_body(
        SensorTree.preset("opensense"), read_orientations_sto(d / "walking_orientations.sto"),
        calibration="anatomical", placement=read_orientations_sto(d / "placement_orientations.sto"),
        heading=HeadingFromSensor("torso_imu", "z"), root_reference="world",
    )  # fmt: skip


def ximu3() -> BodyResult:
    """The x-IMU3 lower-body recording on the devices' own fusion."""
    return run_body(
        SensorTree.preset("lower_body"), read_device_orientations(DATA / "ximu3-lower-body")
    )


def with_filter(tree_name: str, recs: dict[str, ImuRecording], name: str, mode: str,
                **kwargs: Any) -> BodyResult:  # fmt: skip
    """The body model on orientations from a mocapkit filter run on the raw samples."""
    tree = SensorTree.preset(tree_name)
    ori = {
        k: make_filter(name, r.rate_hz).run_recording(r, use_mag=mode == "9d")
        for k, r in recs.items()
        if k in tree.sensor_names
    }
    return run_body(tree, ori, heading_alignment="shared" if mode == "9d" else "pose", **kwargs)


def rms_vs(
    a: BodyResult,
    b: BodyResult,
    names: tuple[str, ...],
    windows: list[tuple[float, float]] | None = None,
) -> dict[str, float]:
    """RMS difference [deg] between two results on a's frames (b interpolated)."""
    x, y = a.body.angles, b.body.angles
    mask = np.ones(x.n_samples, dtype=bool)
    if windows:
        mask[:] = False
        for w0, w1 in windows:
            mask |= (x.time >= w0) & (x.time <= w1)
    out = {}
    for n in names:
        d = np.rad2deg(x.column(n) - np.interp(x.time, y.time, y.column(n)))[mask]
        out[n] = float(np.sqrt(np.nanmean(d**2)))
    return out


def plot_full_body(res: BodyResult, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a = res.body.angles
    groups = [
        ("knee flexion", ["knee_angle_r", "knee_angle_l"]),
        ("hip flexion / adduction", ["hip_flexion_r", "hip_flexion_l", "hip_adduction_r"]),
        ("ankle", ["ankle_angle_r", "ankle_angle_l"]),
        ("pelvis and trunk", ["pelvis_tilt", "pelvis_list", "lumbar_extension"]),
        ("arm", ["arm_flex_r", "elbow_flex_r", "elbow_flex_l"]),
        ("pelvis heading (turns)", ["pelvis_rotation"]),
    ]
    fig, axes = plt.subplots(len(groups), 1, figsize=(12, 13), sharex=True)
    for ax, (title, names) in zip(axes, groups, strict=True):
        for n in names:
            ax.plot(a.time, np.rad2deg(a.column(n)), lw=0.7, label=n)
        ax.set_ylabel("deg")
        ax.set_title(title, fontsize=9, loc="left")
        ax.legend(loc="upper right", fontsize=7)
        ax.grid(alpha=0.3)
    for w0, w1, label in [(52, 79, "sitting"), (95, 115, "walking"), (116, 138.5, "walking")]:
        for ax in axes:
            ax.axvspan(w0, w1, color="0.92", zorder=0)
        axes[0].text((w0 + w1) / 2, 1.02, label, transform=axes[0].get_xaxis_transform(),
                     ha="center", fontsize=8)  # fmt: skip
    axes[-1].set_xlabel("time [s]")
    fig.suptitle("qmt full-body recording, full_body_15 preset, mountings and heading estimated "
                 "automatically", fontsize=10)  # fmt: skip
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_opensense(res: BodyResult, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ref = read_joint_angles_mot(REPO / "tests" / "data" / "opensense_imu_ik_reference.mot")
    a = res.body.angles
    names = ["pelvis_tilt", "hip_flexion_r", "hip_adduction_r", "hip_rotation_r",
             "knee_angle_r", "ankle_angle_r", "hip_flexion_l", "knee_angle_l"]  # fmt: skip
    fig, axes = plt.subplots(4, 2, figsize=(12, 10), sharex=True)
    keep = (a.time >= ref.time[0]) & (a.time <= ref.time[-1])
    for ax, n in zip(axes.ravel(), names, strict=True):
        ax.plot(ref.time, np.rad2deg(ref.column(n)), lw=1.2, label="OpenSim IMU IK")
        ax.plot(a.time[keep], np.rad2deg(a.column(n)[keep]), lw=1.0, ls="--", label="mocapkit")
        ax.set_title(n, fontsize=9, loc="left")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    fig.suptitle("OpenSense walking: mocapkit body model vs OpenSim IMU inverse kinematics "
                 "(deg)", fontsize=10)  # fmt: skip
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_ximu3(device: BodyResult, own: BodyResult, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = ["knee_angle_r", "knee_angle_l", "hip_flexion_r", "hip_flexion_l",
             "ankle_angle_r", "pelvis_rotation"]  # fmt: skip
    fig, axes = plt.subplots(3, 2, figsize=(12, 8), sharex=True)
    t0 = device.body.angles.time[0]
    for ax, n in zip(axes.ravel(), names, strict=True):
        for res, label, ls in ((device, "device fusion", "-"), (own, "mocapkit miller 9D", "--")):
            a = res.body.angles
            ax.plot(a.time - t0, np.rad2deg(a.column(n)), ls=ls, lw=1.0, label=label)
        ax.set_title(n, fontsize=9, loc="left")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    fig.suptitle("x-IMU3 lower body (mountings and heading estimated automatically), deg",
                 fontsize=10)  # fmt: skip
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--plots", help="directory for PNG figures")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if not DATA.is_dir():
        print(f"no data at {DATA}", file=sys.stderr)
        return 1
    fb, fb_s = full_body()
    os_res = opensense()
    xi = ximu3()
    xi_recs = read_imu_recordings(DATA / "ximu3-lower-body")
    qmt_imu = read_qmt_mat(DATA / "full-body-15-imu" / "full_body_example_data.mat").imu
    compared = ("knee_angle_r", "knee_angle_l", "hip_flexion_r", "hip_flexion_l",
                "ankle_angle_r", "ankle_angle_l", "pelvis_tilt")  # fmt: skip
    filters: dict[str, Any] = {"ximu3_lower_body": {}, "full_body_15": {}}
    for name in ("miller", "bachmann"):
        for mode in ("9d", "6d"):
            res = with_filter("lower_body", xi_recs, name, mode)
            filters["ximu3_lower_body"][f"{name}_{mode}"] = rms_vs(res, xi, compared)
        res = with_filter("full_body_15", dict(qmt_imu), name, "6d", start=40.3)
        filters["full_body_15"][f"{name}_6d"] = rms_vs(res, fb, compared, FULL_BODY_WALK)
    report: dict[str, Any] = {
        "full_body_15": {
            "seconds": fb_s,
            "frames": fb.body.angles.n_samples,
            "calibration": fb.calibration.diagnostics,
            "walking": plausibility(fb, FULL_BODY_WALK),
        },
        "opensense": {
            "calibration": os_res.calibration.diagnostics,
            "all": plausibility(os_res, None),
        },
        "ximu3_lower_body": {
            "calibration": xi.calibration.diagnostics,
            "all": plausibility(xi, None),
        },
        "own_filters_vs_recording_fusion_rms_deg": filters,
    }
    if args.plots:
        out = Path(args.plots)
        out.mkdir(parents=True, exist_ok=True)
        plot_full_body(fb, out / "body_full_body_15.png")
        plot_opensense(os_res, out / "body_opensense_vs_opensim.png")
        plot_ximu3(xi, with_filter("lower_body", xi_recs, "miller", "9d"),
                   out / "body_ximu3_lower_body.png")  # fmt: skip
    if args.json:
        print(json.dumps(report, indent=2, default=float))
        return 0
    for rec, body in report.items():
        if rec.startswith("own_filters"):
            continue
        print(f"## {rec}")
        cal = body["calibration"]
        print(
            "calibration:",
            {k: (round(v, 1) if isinstance(v, float) else v) for k, v in cal.items()},
        )
        table = body.get("walking") or body["all"]
        print("| coordinate | p2 [deg] | p98 [deg] | largest step [deg] |")
        print("|---|---|---|---|")
        for name in KEY:
            if name in table:
                r = table[name]
                print(
                    f"| {name} | {r['p2_deg']:.1f} | {r['p98_deg']:.1f} | {r['max_step_deg']:.1f} |"
                )
        print()
    print("## mocapkit filters on the raw samples vs the recording's own fusion, RMS [deg]")
    for rec, per in filters.items():
        print(f"| {rec} | " + " | ".join(compared) + " |")
        print("|---|" + "---|" * len(compared))
        for label, d in per.items():
            print(f"| {label} | " + " | ".join(f"{d[c]:.1f}" for c in compared) + " |")
        print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
