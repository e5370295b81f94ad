"""The whole inertial chain against a known truth: marker-reconstructed human motion ->
virtual IMUs with unknown mountings -> raw samples -> filter -> calibration -> body model.

    python -m benchmarks.body_closed_loop [--seeds 3] [--write-docs]

Truth: OpenSim's gait2392 walk (``subject01_walk1.trc`` in ../shared), reconstructed by
mocapkit (``mocapkit.reconstruct``); its lower-body coordinates drive the ``lower_body``
sensor tree (pelvis, thighs, shanks, feet), after 3 s standing in the N-pose and a 1 s
blend into the walk's first frame; the pelvis moves forward at the walk's mean speed.
Each segment gets a virtual IMU at its middle, mounted up to 30 deg off the segment's axes
(a random axis per sensor and seed), with consumer-grade errors (noise, bias and its
drift, scale and misalignment, ``ImuErrorModel.consumer_grade``). Its raw samples go
through ``polaris-body`` (9D and 6D), the body calibration (from the held pose, and
automatic) and the body model. Reported: joint-angle RMSE per coordinate against the
truth over the walk [deg], and the mounting error per segment [deg], mean over seeds.

First version (issue 13): lower body only; the arms and the full 15-sensor tree, the
magnetic disturbance near the floor and dropped packets are not simulated yet.
"""

from __future__ import annotations

import argparse
import math
import warnings
from pathlib import Path

import numpy as np

from benchmarks._docs import write_section
from mocapkit.body.calibration import HeadingFixed, pose_coordinates
from mocapkit.body.pipeline import run_body
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.body.simulate import segment_poses, virtual_suit
from mocapkit.geometry import quat_conj, quat_mul
from mocapkit.imu.filters import make_filter
from mocapkit.imu.metrics import total_error

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
TRIAL = SHARED / "opensim" / "gait2392" / "subject01_walk1.trc"
RATE = 100.0
STILL_S, BLEND_S = 3.0, 1.0
MAX_MOUNT_DEG = 30.0
HEADING = 0.6  # where the subject faces [rad from world x]


def truth_motion(tree: SensorTree) -> tuple[np.ndarray, dict[str, np.ndarray], float]:
    """Time (N,), {coordinate: (N,) rad} of the tree, and the walk's start time."""
    import mocapkit

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = mocapkit.reconstruct(TRIAL, height_m=1.80)
    a = rec.angles
    t_walk = np.arange(a.time[0], a.time[-1], 1.0 / RATE)
    walk = {}
    for name in tree.coordinate_names:
        if name in a.names and name != "pelvis_rotation":
            v = a.column(name)
            good = np.isfinite(v)
            walk[name] = np.interp(t_walk, a.time[good], v[good])
    npose = pose_coordinates(tree, "npose")
    n_still, n_blend = round(STILL_S * RATE), round(BLEND_S * RATE)
    s = 0.5 - 0.5 * np.cos(np.linspace(0.0, np.pi, n_blend))
    coords = {}
    for name in tree.coordinate_names:
        start = npose.get(name, 0.0)
        w = walk.get(name, np.zeros_like(t_walk))
        coords[name] = np.concatenate([np.full(n_still, start), start + s * (w[0] - start), w])
    n = n_still + n_blend + t_walk.size
    return np.arange(n) / RATE, coords, (n_still + n_blend) / RATE


def run(seed: int, tree: SensorTree, time: np.ndarray, coords: dict[str, np.ndarray],
        t_walk: float) -> dict[str, dict[str, float]]:  # fmt: skip
    rng = np.random.default_rng(seed)
    segs = segment_poses(tree, time, coords, heading_rad=HEADING, speed=1.2, walk_start_s=STILL_S)
    recs, mounts = virtual_suit(tree, segs, rng, max_mount_deg=MAX_MOUNT_DEG)
    figures: dict[str, dict[str, float]] = {}
    walk = time >= t_walk
    for mode in ("9d", "6d"):
        oris = {
            name: make_filter("polaris-body", RATE).run_recording(rec, use_mag=mode == "9d")
            for name, rec in recs.items()
        }
        runs = ["npose", "auto"] + (["auto (pose headings)"] if mode == "9d" else [])
        for calibration in runs:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                # 6D: each sensor's world has its own heading; the automatic calibration
                # aligns them from the pose ("pose"), as docs/body.md says to
                align = "pose" if (mode == "6d" and calibration == "auto") else "shared"
                if calibration == "auto (pose headings)":
                    align = "pose"
                res = run_body(
                    tree, oris, calibration=calibration.split(" ")[0],
                    window=(0.5, STILL_S - 0.5),
                    heading=HeadingFixed(HEADING) if calibration == "npose" else None,
                    heading_alignment=align,
                )  # fmt: skip
            a = res.body.angles
            key = f"{mode} {calibration}"
            row: dict[str, float] = {}
            for name in a.names:
                if name == "pelvis_rotation" or name not in coords:
                    continue
                est = np.interp(time[walk], a.time, a.column(name))
                err = np.degrees(est - coords[name][walk])
                err = (err + 180.0) % 360.0 - 180.0
                row[name] = float(np.sqrt(np.nanmean(err**2)))
            for seg in tree.segments:
                q_est = res.calibration.segments[seg.name].q_sensor_segment
                q_true = quat_conj(mounts[seg.name])  # q_sensor_segment
                row[f"mount {seg.name}"] = math.degrees(
                    float(total_error(quat_mul(q_est, quat_conj(q_true))[None])[0])
                )
            figures[key] = row
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    if not TRIAL.exists():
        raise SystemExit(f"needs {TRIAL}")
    tree = SensorTree.preset("lower_body")
    time, coords, t_walk = truth_motion(tree)
    per_seed = [run(seed, tree, time, coords, t_walk) for seed in range(args.seeds)]
    keys = list(per_seed[0])
    names = list(per_seed[0][keys[0]])
    mean = {k: {n: float(np.mean([s[k][n] for s in per_seed])) for n in names} for k in keys}
    angle_rows = [n for n in names if not n.startswith("mount ")]
    mount_rows = [n for n in names if n.startswith("mount ")]
    lines = ["| coordinate | " + " | ".join(keys) + " |", "|---|" + "---:|" * len(keys)]
    for n in angle_rows:
        lines.append(f"| {n} | " + " | ".join(f"{mean[k][n]:.2f}" for k in keys) + " |")
    lines.append(
        "| **mean** | "
        + " | ".join(f"**{np.mean([mean[k][n] for n in angle_rows]):.2f}**" for k in keys)
        + " |"
    )
    lines += [
        "",
        "| mounting error [deg] | " + " | ".join(keys) + " |",
        "|---|" + "---:|" * len(keys),
    ]
    for n in mount_rows:
        lines.append(f"| {n[6:]} | " + " | ".join(f"{mean[k][n]:.2f}" for k in keys) + " |")
    text = (
        f"`python -m benchmarks.body_closed_loop --seeds {args.seeds}` (method and limits in "
        "the module docstring: gait2392 walk reconstructed from its markers, lower-body "
        "tree, virtual IMUs up to 30 deg off, consumer-grade errors, polaris-body, "
        "calibration from the held N-pose with the heading given or automatic). "
        "Joint-angle RMSE against the truth over the walk [deg], mean over seeds; target "
        "(issue 13): <= 2 deg on average, <= 4 on every coordinate. In 6D each sensor's "
        "heading is its own, so a pose calibration folds that heading into the mounting: "
        "the 6D mounting errors measure that, not a wrong placement; the automatic "
        "calibration in 6D aligns the headings from the pose (heading_alignment=pose; an "
        "earlier version of this table used 'shared' there, which is wrong for 6D).\n\n"
        + "\n".join(lines)
    )
    print(text)
    if args.write_docs:
        write_section("Body: closed loop from marker-side truth (inertial chain)", text)


if __name__ == "__main__":
    main()
