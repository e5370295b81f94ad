"""Whole-body retargeting per robot on the recordings in ../shared (issue 14's table).

    python -m benchmarks.retarget_humanoids [--write-docs]

Every marker trial (gait2392 walk TRC, walking2 and CMU 85_02 C3D: reconstructed by
mocapkit on the way) and the 15-IMU full-body recording (through the body model) onto
every packaged humanoid. Figures from ``mocapkit.retarget.metrics``; ``end-to-end fps``
counts the whole call (reading, reconstruction or body model, targets, QP, collision
count) in this process after the imports and one warm-up call (numba's kernels loaded;
the command's own ``--json`` fps counts the whole process: 65 frames/s for G1 on the
gait2392 TRC, 2.3 s), ``solve fps`` the QP loop alone. Every robot with the collision
guard (the default: every frame checked on the meshes, a colliding step steered round
with hard distance rows between convex hulls, or the limbs in touch stopped short) and
without it (``--allow-collisions``), to show what the guard removes and what it costs.
GMR's published 35-70 frames/s (desktop) is quoted, not measured here.
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

from benchmarks._docs import write_section

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
INPUTS = [
    ("gait2392 walk (TRC)", SHARED / "opensim/gait2392/subject01_walk1.trc", 1.80),
    ("walking2 (C3D)", SHARED / "c3d/walking2.c3d", None),
    ("CMU 85_02 (C3D)", SHARED / "c3d/cmu_85_02.c3d", None),
    ("15-IMU full body", SHARED / "full-body-15-imu/full_body_example_data.mat", None),
]
ROBOTS = ("g1", "talos", "romeo", "icub", "robonaut2")


def main() -> None:
    from mocapkit.retarget.run import retarget

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    rows = []
    present = [(path, height) for _, path, height in INPUTS if path.exists()]
    if present:  # warm-up, not reported: numba's kernels compiled or loaded, first QPs
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            retarget(present[0][0], ROBOTS[0], height_m=present[0][1])
    for label, path, height in INPUTS:
        if not path.exists():
            continue
        runs = [(r, True) for r in ROBOTS] + [(r, False) for r in ROBOTS]
        for robot, guard in runs:
            t0 = time.perf_counter()
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    res = retarget(path, robot, height_m=height, guard_collisions=guard)
            except Exception as exc:
                rows.append(f"| {label} | {robot} | failed: {str(exc)[:90]} |||||||")
                print(rows[-1])
                continue
            secs = time.perf_counter() - t0
            f = res.figures
            n = res.solution.time.size
            kp = f["keypoint_rmse_mm"]
            worst = max((k for k in kp if k != "mean"), key=lambda k: kp[k])
            lim = f["limit_violations"]
            coll = f["collisions"]
            name = robot if guard else f"{robot}, no guard"
            sol = res.solution
            rows.append(
                f"| {label} | {name} | {n} | {kp['mean']} ({worst} {kp[worst]}) | "
                f"{f['foot_skate_mm']} | {f['ground_penetration']['frames']} | "
                f"{lim['position']} / {lim['velocity']} | {coll['frames']} "
                f"({coll['pairs'][0].split(':')[0] if coll['pairs'] else '-'}) | "
                f"{len(sol.kept_apart)} / {len(sol.stopped)} | "
                f"{n / secs:.0f} | {n / sol.solve_seconds:.0f} |"
            )
            print(rows[-1])
    text = (
        "`python -m benchmarks.retarget_humanoids` (method in the module docstring). Target "
        "(issue 14): zero limit violations and collisions, foot skating below 2 mm/frame "
        "during contact, >= 1,000 frames/s offline on one core for G1.\n\n"
        "| input | robot | frames | keypoint RMS mm (worst) | foot skate mm/frame | "
        "frames below ground | limit violations pos / vel | collision frames (pair) | "
        "guard steered / stopped short | end-to-end fps | solve fps |\n"
        "|---|---|---:|---|---:|---:|---|---|---|---:|---:|\n" + "\n".join(rows)
    )
    print(text)
    if args.write_docs:
        write_section("Retargeting onto humanoids", text)


if __name__ == "__main__":
    main()
