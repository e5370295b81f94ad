"""Heading drift without a magnetometer on the real recordings: hip and shoulder rotation
with the headings aligned at the pose only, and kept aligned by the joints.

    python -m benchmarks.body_heading_drift [--write-docs]

Recordings in ../shared: the qmt 15-IMU full body (100 s, no magnetometer: the longest
here) and the x-IMU3 lower body (18.6 s, with magnetometers). Raw samples through
``polaris-body`` 6D, the automatic calibration, then either ``heading_alignment=pose``
(each sensor's heading aligned at the held pose, then left to drift) or ``joints``
(``mocapkit.body.joint_headings``: kept aligned by the joint centres' accelerations).
Reported per coordinate: the drift as the trend of the angle over the recording (a
least-squares line, deg/min: a person's hip rotation has no trend over minutes; drift
does) and, where a magnetometer gives a reference (x-IMU3: polaris-body 9D through the
same body model), the RMS difference against it. Also: the heading correction the joints
applied per sensor over the recording (last minus first, deg), and a check that needs no
reference: knees turn about one axis, so the child segment's rotation away from
that axis in the parent's frame should stay as small at the end as at the start; a heading
drifting between the two sensors makes it grow.
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np

from benchmarks._docs import write_section
from mocapkit.body.joint_headings import align_headings_by_joints
from mocapkit.body.pipeline import run_body
from mocapkit.body.recordings import read_raw, recording_format, run_filter
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.geometry import quat_conj, quat_mul, quat_to_rotvec

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
RECORDINGS = (
    ("qmt 15-IMU full body", SHARED / "full-body-15-imu" / "full_body_example_data.mat",
     "full_body_15", 40.3),
    ("x-IMU3 lower body", SHARED / "ximu3-lower-body", "lower_body", None),
)  # fmt: skip
COORDS = ("hip_rotation_r", "hip_rotation_l", "arm_rot_r", "arm_rot_l")


def _angles(tree, oris, start, align):  # type: ignore[no-untyped-def]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return run_body(tree, oris, start=start, heading_alignment=align).body.angles


def _trend_deg_per_min(t: np.ndarray, v: np.ndarray) -> float:
    good = np.isfinite(v)
    slope = np.polyfit(t[good], np.degrees(np.unwrap(v[good])), 1)[0]
    return float(slope * 60.0)


# knees only: the forearm segment carries pronation, so an elbow is not a hinge here
HINGES = (("femur_r", "tibia_r"), ("femur_l", "tibia_l"))


def _run(tree, oris, start, align):  # type: ignore[no-untyped-def]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return run_body(tree, oris, start=start, heading_alignment=align)


def hinge_off_axis(res, parent: str, child: str) -> tuple[float, float]:  # type: ignore[no-untyped-def]
    """A knee turns about one axis: the rotation of the child in the parent's
    frame away from its main axis (principal direction of the rotation vectors) [deg],
    RMS over the first and the last third of the recording. Needs no reference: a
    heading that drifts between the two sensors turns the child about the vertical,
    which leaves that axis, and grows."""
    qp, qc = res.segments[parent].quat, res.segments[child].quat
    rv = quat_to_rotvec(quat_mul(quat_conj(qp), qc))
    rv = rv[np.isfinite(rv).all(axis=1)]
    axis = np.linalg.svd(rv - 0.0, full_matrices=False)[2][0]
    off = np.degrees(np.linalg.norm(rv - np.outer(rv @ axis, axis), axis=1))
    third = max(1, off.size // 3)
    return (float(np.sqrt(np.mean(off[:third] ** 2))), float(np.sqrt(np.mean(off[-third:] ** 2))))


def measure(path: Path, preset: str, start: float | None) -> tuple[list[str], list[str], list[str]]:
    tree = SensorTree.preset(preset)
    raw = read_raw(path, recording_format(path))
    six = run_filter(raw, "polaris-body", "6d")
    res_pose = _run(tree, six, start, "pose")
    turned, info = align_headings_by_joints(tree, six, raw)
    res_joints = _run(tree, turned, start, "joints")
    pose, joints = res_pose.body.angles, res_joints.body.angles
    hinge_rows = []
    for parent, child in HINGES:
        if parent in res_pose.segments and child in res_pose.segments:
            a = hinge_off_axis(res_pose, parent, child)
            b = hinge_off_axis(res_joints, parent, child)
            hinge_rows.append(f"| {parent} -> {child} | {a[0]:.1f} -> {a[1]:.1f} | "
                              f"{b[0]:.1f} -> {b[1]:.1f} |")  # fmt: skip
    ref = None
    if all(r.has_mag for r in raw.values()):
        ref = _angles(tree, run_filter(raw, "polaris-body", "9d"), start, "shared")
    rows = []
    for c in COORDS:
        if c not in pose.names:
            continue
        cells = [f"{_trend_deg_per_min(a.time, a.column(c)):+.1f}" for a in (pose, joints)]
        if ref is not None:
            for a in (pose, joints):
                d = np.degrees(np.interp(ref.time, a.time, a.column(c)) - ref.column(c))
                d = (d + 180.0) % 360.0 - 180.0
                cells.append(f"{float(np.sqrt(np.nanmean(d * d))):.1f}")
        else:
            cells += ["-", "-"]
        rows.append(f"| {c} | " + " | ".join(cells) + " |")
    corr = [
        f"{p.child} {np.degrees(p.delta[-1] - p.delta[0]):+.1f} ({p.windows}/{p.windows_total})"
        for p in info.pairs
    ]
    return rows, corr, hinge_rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    parts = []
    for label, path, preset, start in RECORDINGS:
        if not path.exists():
            raise SystemExit(f"needs {path}")
        rows, corr, hinges = measure(path, preset, start)
        parts.append(
            f"**{label}**\n\n| coordinate | trend, pose only [deg/min] | trend, joints "
            "[deg/min] | RMS vs 9D, pose only [deg] | RMS vs 9D, joints [deg] |\n"
            "|---|---:|---:|---:|---:|\n" + "\n".join(rows) + "\n\nHeading correction by the "
            "joints over the recording (child sensor, deg, windows used): "
            + "; ".join(corr)
            + "\n\n| hinge | off-axis rotation, pose only: first -> last third [deg] | "
            "joints: first -> last third [deg] |\n|---|---:|---:|\n" + "\n".join(hinges)
        )
        print(parts[-1], flush=True)
    text = (
        "`python -m benchmarks.body_heading_drift` (method in the module docstring): raw "
        "samples through polaris-body 6D; headings aligned at the pose only, or kept "
        "aligned by the joints (`--heading-alignment joints`, the default in 6D).\n\n"
        + "\n\n".join(parts)
    )
    print(text)
    if args.write_docs:
        write_section("Body: heading drift without a magnetometer (real recordings)", text)


if __name__ == "__main__":
    main()
