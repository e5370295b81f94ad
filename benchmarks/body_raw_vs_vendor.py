"""Raw samples through our filters against the vendor's own orientations, through the same
body model: do they give the same joint angles on real recordings?

    python -m benchmarks.body_raw_vs_vendor [--write-docs]

Recordings in ../shared: the qmt 15-IMU full body (``full_body_15``, from 40.3 s) and the
x-IMU3 lower body (``lower_body``). Each: the device's orientations and the raw samples
through ``polaris-body`` (9D, 6D, and 6D with the headings kept aligned by the joints,
``mocapkit.body.joint_headings``) and ``bachmann`` (9D), each calibrated automatically
and run through the body model; reported: the RMS difference [deg] per coordinate group
against the vendor's result, mean and worst coordinate (``pelvis_rotation`` left out: it
is the heading, which 6D does not have). A difference is not an error of either side:
it is how far the joint angles depend on the orientation source. Issue 13's target: the
same within a few degrees.
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np

from benchmarks._docs import write_section
from mocapkit.body.joint_headings import align_headings_by_joints
from mocapkit.body.pipeline import run_body
from mocapkit.body.recordings import load_orientations, read_raw, run_filter
from mocapkit.body.sensor_tree import SensorTree

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
# label, path, tree, start [s], has a magnetometer (else every source is 6D: headings
# aligned from the pose, heading_alignment="pose")
RECORDINGS = (
    ("qmt 15-IMU full body", SHARED / "full-body-15-imu" / "full_body_example_data.mat",
     "full_body_15", 40.3, False),
    ("x-IMU3 lower body", SHARED / "ximu3-lower-body", "lower_body", None, True),
)  # fmt: skip
SOURCES = (("polaris-body", "9d"), ("polaris-body", "9d joints"), ("polaris-body", "6d"),
           ("polaris-body", "6d joints"), ("bachmann", "9d"))  # fmt: skip


def _angles(tree: SensorTree, oris: dict, start: float | None, align: str):  # type: ignore[no-untyped-def, type-arg]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return run_body(tree, oris, start=start, heading_alignment=align).body.angles


def compare(
    path: Path, preset: str, start: float | None, has_mag: bool
) -> dict[str, tuple[float, str, float]]:
    tree = SensorTree.preset(preset)
    fmt = "qmt-mat" if path.suffix == ".mat" else "device"
    vendor = _angles(tree, load_orientations(path, fmt), start, "hinges" if has_mag else "pose")
    out = {}
    samples = read_raw(path, fmt)
    for name, mode in SOURCES:
        align = "hinges" if (has_mag and mode.startswith("9d")) else "pose"
        oris = run_filter(samples, name, mode.split(" ")[0])
        if mode.endswith("joints"):  # 6D headings kept aligned by the joints
            oris, _ = align_headings_by_joints(tree, oris, samples)
            align = "joints"  # as body angles --heading-alignment joints does
        raw = _angles(tree, oris, start, align)
        diffs = {}
        for coord in vendor.names:
            if coord == "pelvis_rotation" or coord not in raw.names:
                continue
            a = np.interp(vendor.time, raw.time, raw.column(coord))
            d = np.degrees(a - vendor.column(coord))
            d = (d + 180.0) % 360.0 - 180.0
            diffs[coord] = float(np.sqrt(np.nanmean(d * d)))
        worst = max(diffs, key=lambda k: diffs[k])
        out[f"{name} {mode}"] = (float(np.mean(list(diffs.values()))), worst, diffs[worst])
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    lines = [
        "| recording | raw samples through | mean RMS difference [deg] | worst coordinate |",
        "|---|---|---:|---|",
    ]
    for label, path, preset, start, has_mag in RECORDINGS:
        if not path.exists():
            raise SystemExit(f"needs {path}")
        for source, (mean, worst, worst_deg) in compare(path, preset, start, has_mag).items():
            lines.append(f"| {label} | {source} | {mean:.2f} | {worst} {worst_deg:.1f} |")
            print(lines[-1], flush=True)
    text = (
        "`python -m benchmarks.body_raw_vs_vendor` (method in the module docstring; both "
        "sides calibrated automatically): joint angles from our filters on the raw samples "
        "against those from the vendor's orientations. With a magnetometer (9D and the "
        "x-IMU3's own orientations) both sides use the 9D default, heading_alignment=hinges "
        "(1.72 deg for polaris-body 9D and 4.78 for bachmann with the shared heading, the "
        "default before 2026-11-27). Without a magnetometer (6D, and "
        "every source of the qmt recording) the headings are aligned from the held pose "
        "(heading_alignment=pose; an earlier version used the shared option there, which "
        "gave 29 deg on qmt and 13.5 on x-IMU3 6D); '6d joints' keeps them aligned "
        "afterwards through the joints (the default of body angles in 6D; there the hinge "
        "calibration is used, which the vendor's side, 6D worlds aligned at the pose only, "
        "does not: part of the qmt difference); '9d joints' the same on 9D samples (not the "
        "default). On qmt that brings our raw samples to ~4 deg of the vendor's orientations "
        "(from 15.1 with the pose alone: the arms' headings drifted apart); on the x-IMU3's "
        "18 s the hips, whose joint the pelvis sensor does not show clearly, are not "
        "followed, so hip rotation stays 15-20 deg off. OpenSense's Xsens export is not in "
        "the table: it has no gyroscope columns, so no filter can run on it (its reader says "
        "so, naming the sensor).\n\n" + "\n".join(lines)
    )
    print(text)
    if args.write_docs:
        write_section(
            "Body: raw samples through our filters against the vendor's orientations", text
        )


if __name__ == "__main__":
    main()
