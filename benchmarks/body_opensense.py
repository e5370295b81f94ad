"""Body kinematics on the OpenSense walking recording, side by side with OpenSim's IMU
placer + IMU inverse kinematics (Rajagopal 2015 model, the example's own setups).

    .venv/bin/python -m benchmarks.body_opensense [--repeats 20] [--json]
        [--write-reference tests/data/opensense_ik_reference.mot]

Reports frames per second of both (the same 650 frames, 10.5-17 s), OpenSim's mean
orientation residual, our streaming per-frame latency, and the RMS difference between our
joint angles and OpenSim's on every coordinate both models have. Needs the bench extra
(``pip install -e '.[bench]'``, opensim 4.6) and ../shared/data/opensense.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from mocapkit.body.calibration import HeadingFromSensor
from mocapkit.body.joint_angles import joint_angles_reference
from mocapkit.body.kinematics import BodyStream
from mocapkit.body.pipeline import BodyResult, run_body
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.geometry import quat_normalize
from mocapkit.io.joint_angles_mot import read_joint_angles_mot, write_joint_angles_mot
from mocapkit.io.opensense import read_orientations_sto
from mocapkit.series import JointAngleSeries, OrientationSeries

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data" / "opensense"
IK_RANGE = (10.5, 17.0)  # the example's imuInverseKinematics_Setup.xml
COMPARED = (
    "pelvis_tilt", "pelvis_list", "pelvis_rotation",
    "hip_flexion_r", "hip_adduction_r", "hip_rotation_r", "knee_angle_r", "ankle_angle_r",
    "hip_flexion_l", "hip_adduction_l", "hip_rotation_l", "knee_angle_l", "ankle_angle_l",
)  # fmt: skip


def run_opensim(workdir: Path) -> dict[str, object]:
    """IMU placer + IMU IK as in the example; returns times, residual and the motion."""
    import opensim as osim

    osim.Logger.setLevelString("error")
    for f in (
        "Rajagopal2015_opensense.osim",
        "walking_orientations.sto",
        "placement_orientations.sto",
    ):
        shutil.copy(DATA / f, workdir / f)
    cwd = os.getcwd()
    os.chdir(workdir)
    try:
        t0 = time.perf_counter()
        placer = osim.IMUPlacer(str(DATA / "imuPlacer_Setup.xml"))
        placer.set_model_file("Rajagopal2015_opensense.osim")
        placer.set_orientation_file_for_calibration("placement_orientations.sto")
        placer.run(False)
        placer.getCalibratedModel().printToXML("calibrated.osim")
        t1 = time.perf_counter()
        ik = osim.IMUInverseKinematicsTool(str(DATA / "imuInverseKinematics_Setup.xml"))
        ik.set_model_file("calibrated.osim")
        ik.set_orientations_file("walking_orientations.sto")
        ik.set_results_directory(".")
        ik.set_report_errors(True)
        ik.run(False)
        t2 = time.perf_counter()
    finally:
        os.chdir(cwd)
    motion = read_joint_angles_mot(workdir / "walking_motion.sto")
    errors = sorted(workdir.glob("*orientationErrors*.sto"))
    residual = None
    if errors:
        from mocapkit.io.opensim_table import read_table

        tab = read_table(errors[0])
        residual = float(np.rad2deg(np.nanmean(tab.data)))
    return {"placer_s": t1 - t0, "ik_s": t2 - t1, "motion": motion, "residual_deg": residual}


def run_ours() -> tuple[BodyResult, float, float]:
    """End to end (read both files, calibrate, angles) and compute-only times [s]."""
    tree = SensorTree.preset("opensense")
    t0 = time.perf_counter()
    walk = read_orientations_sto(DATA / "walking_orientations.sto")
    place = read_orientations_sto(DATA / "placement_orientations.sto")
    t1 = time.perf_counter()
    res = run_body(
        tree, walk, calibration="anatomical", placement=place,
        heading=HeadingFromSensor("torso_imu", "z"), root_reference="world",
        start=IK_RANGE[0], stop=IK_RANGE[1],
    )  # fmt: skip
    t2 = time.perf_counter()
    return res, t2 - t0, t2 - t1


def locked_lumbar(res: BodyResult) -> JointAngleSeries:
    """Our angles with OpenSim's model constraint on the pelvis: its lumbar joint is locked,
    so its pelvis is a compromise between the pelvis and torso IMUs (here their chordal
    mean). Shows which part of the difference is the model, not the measurement."""
    tree = SensorTree.preset("opensense")
    segs = dict(res.segments)
    p, t = segs["pelvis"].quat, segs["torso"].quat
    t = np.where((np.sum(p * t, axis=1) < 0.0)[:, None], -t, t)
    segs["pelvis"] = OrientationSeries(segs["pelvis"].time, quat_normalize(p + t), name="pelvis")
    return joint_angles_reference(tree, segs, res.calibration.q_world_ground).angles


def stream_latency(tree_name: str, n_frames: int = 3000) -> dict[str, float]:
    """Per-frame BodyStream.update (dict in, angles out) in microseconds."""
    import logging

    logging.getLogger("mocapkit.body").setLevel(logging.ERROR)  # reused sensors: odd poses
    tree = SensorTree.preset(tree_name)
    walk = read_orientations_sto(DATA / "walking_orientations.sto")
    place = read_orientations_sto(DATA / "placement_orientations.sto")
    # any sensor data of the right size: reuse the 8 OpenSense sensors cyclically
    src = list(walk.values())
    mapping = {s.name: src[i % len(src)].name + f"#{i}" for i, s in enumerate(tree.segments)}
    tree = tree.with_sensor_names(mapping)
    feeds = {mapping[s.name]: src[i % len(src)] for i, s in enumerate(tree.segments)}
    cal_src = {mapping[s.name]: place[src[i % len(src)].name] for i, s in enumerate(tree.segments)}
    res = run_body(tree, feeds, calibration="npose", placement=cal_src)
    stream = BodyStream(tree, res.calibration)
    q = np.stack([feeds[s].quat for s in tree.sensor_names], axis=1)
    t = walk["pelvis_imu"].time
    frames = [
        {s: q[n % len(q), k] for k, s in enumerate(tree.sensor_names)} for n in range(n_frames)
    ]
    stream.update(frames[0], 0.0)  # compile
    dt = np.empty(n_frames)
    for n in range(n_frames):
        a = time.perf_counter()
        stream.update(frames[n], float(t[n % len(t)] + n * 1e-3))
        dt[n] = time.perf_counter() - a
    return {
        "sensors": len(tree.segments),
        "p50_us": float(np.percentile(dt, 50) * 1e6),
        "p99_us": float(np.percentile(dt, 99) * 1e6),
    }


def compare(ours: JointAngleSeries, ref: JointAngleSeries) -> dict[str, dict[str, float]]:
    """RMS and mean difference [deg] per coordinate on OpenSim's frames."""
    out = {}
    for c in COMPARED:
        r = np.rad2deg(ref.column(c))
        o = np.rad2deg(np.interp(ref.time, ours.time, ours.column(c)))
        d = o - r
        if c == "pelvis_rotation":  # a heading: compare modulo whole turns
            d = (d + 180.0) % 360.0 - 180.0
        out[c] = {"rms_deg": float(np.sqrt(np.mean(d**2))), "mean_deg": float(d.mean()),
                  "opensim_range_deg": float(np.ptp(r))}  # fmt: skip
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--write-reference", help="save OpenSim's IK angles (compared columns) as .mot")
    args = ap.parse_args(argv)
    if not DATA.is_dir():
        print(f"no data at {DATA}", file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory() as tmp:
        osim_res = run_opensim(Path(tmp))
    ref: JointAngleSeries = osim_res["motion"]  # type: ignore[assignment]
    n_ref = ref.n_samples
    run_ours()  # warm-up (numba compile, imports)
    runs = [run_ours() for _ in range(args.repeats)]
    ours = runs[0][0].body.angles
    e2e = float(np.median([r[1] for r in runs]))
    compute = float(np.median([r[2] for r in runs]))
    diff = compare(ours, ref)
    diff_locked = compare(locked_lumbar(runs[0][0]), ref)
    streams = [stream_latency("opensense"), stream_latency("full_body_15")]
    report = {
        "frames": n_ref,
        "opensim": {
            "ik_s": osim_res["ik_s"], "placer_s": osim_res["placer_s"],
            "frames_per_s": n_ref / float(osim_res["ik_s"]),  # type: ignore[arg-type]
            "mean_orientation_residual_deg": osim_res["residual_deg"],
        },
        "ours": {
            "end_to_end_s": e2e, "frames_per_s_end_to_end": ours.n_samples / e2e,
            "compute_s": compute, "frames_per_s_compute": ours.n_samples / compute,
        },
        "speedup_end_to_end": (ours.n_samples / e2e) / (n_ref / float(osim_res["ik_s"])),  # type: ignore[arg-type]
        "streaming": streams,
        "rms_difference": diff,
        "rms_difference_locked_lumbar": diff_locked,
    }  # fmt: skip
    if args.write_reference:
        cols = np.column_stack([ref.column(c) for c in COMPARED])
        write_joint_angles_mot(
            args.write_reference, JointAngleSeries(ref.time, COMPARED, cols, name="opensim_imu_ik")
        )
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    o: dict = report["opensim"]  # type: ignore[assignment]
    u: dict = report["ours"]  # type: ignore[assignment]
    print(f"OpenSense walking, {n_ref} frames ({IK_RANGE[0]}-{IK_RANGE[1]} s)")
    print(
        f"  OpenSim IMU IK: {o['ik_s']:.2f} s = {o['frames_per_s']:.0f} frames/s "
        f"(placer {o['placer_s']:.2f} s), mean orientation residual "
        f"{o['mean_orientation_residual_deg']:.2f} deg"
    )
    print(
        f"  mocapkit: end to end {u['end_to_end_s'] * 1e3:.1f} ms = "
        f"{u['frames_per_s_end_to_end']:.0f} frames/s; compute {u['compute_s'] * 1e3:.2f} ms = "
        f"{u['frames_per_s_compute']:.0f} frames/s"
    )
    print(f"  speed-up end to end: {report['speedup_end_to_end']:.0f}x")
    for s in streams:
        print(
            f"  streaming, {s['sensors']} sensors: p50 {s['p50_us']:.1f} us, "
            f"p99 {s['p99_us']:.1f} us per frame"
        )
    print(
        "\n| coordinate | RMS difference [deg] | mean difference [deg] | "
        "RMS, pelvis as OpenSim's (locked lumbar) [deg] | OpenSim range [deg] |"
    )
    print("|---|---|---|---|---|")
    for c, d in diff.items():
        print(
            f"| {c} | {d['rms_deg']:.2f} | {d['mean_deg']:+.2f} | "
            f"{diff_locked[c]['rms_deg']:.2f} | {d['opensim_range_deg']:.1f} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
