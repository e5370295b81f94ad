"""Marker reconstruction as a user times it: whole processes, mocapkit beside OpenSim 4.6's
IK tool, in one run; then direct marker control against IK on every C3D in ../shared.

Run: ``.venv/bin/python -m benchmarks.markers_end_to_end [--write-docs] [--repeat 3]``
(needs ``make setup-bench`` for OpenSim and ``../shared/data``).

Each side is one process from its command to its files written, timed from outside (the
user's stopwatch; best and median of ``--repeat``):

- OpenSim: ``python -c "import opensim; opensim.InverseKinematicsTool(SETUP).run()"`` with
  the gait2392 tutorial's model (scaled by OpenSim's Scale tool) and IK setup;
- mocapkit: ``mocapkit markers reconstruct TRIAL --static STATIC --ik-setup SETUP
  --height-m 1.8034 --mass-kg 72.6 -o out.mot --json`` (the same markers, weights,
  coordinate tasks and time range; the scaling from the static trial included, which
  OpenSim's run does not do: its model was scaled beforehand).

Trials: the tutorial walk (0.5-2.5 s, 121 frames at 60 Hz) and a long trial made of it
(the walk forward, then backward in time, and so on: positions stay continuous) of at
least 10,000 frames. Both tools run with their defaults (BLAS threads as installed).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("MOCAPKIT_SHARED_DATA", REPO.parent / "shared" / "data"))
GAIT = DATA / "opensim" / "gait2392"
DOCS = REPO / "docs" / "benchmarks.md"
SECTION = "## Marker reconstruction end to end (whole processes, beside OpenSim)"
HEIGHT, MASS = "1.8034", "72.6"
LONG_FRAMES = 10_000
OPENSIM_RUN = (
    "import opensim as o, sys; o.Logger.setLevelString('error'); "
    "o.InverseKinematicsTool(sys.argv[1]).run()"
)


def _load() -> str:
    try:
        return " ".join(f"{v:.2f}" for v in os.getloadavg())
    except OSError:
        return "n/a"


def _timed(cmd: list[str], cwd: Path) -> tuple[float, str]:
    t0 = time.perf_counter()
    out = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - t0
    if out.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({out.returncode}): {out.stderr[-2000:]}")
    return seconds, out.stdout


def long_trial(path: Path, frames: int = LONG_FRAMES) -> int:
    """The tutorial walk tiled forward and backward in time to ``frames`` frames (TRC)."""
    from mocapkit.io.trc import read_trc, write_trc
    from mocapkit.markers.trajectories import MarkerTrajectories

    walk = read_trc(GAIT / "subject01_walk1.trc", units="mm")
    blocks, n, k = [], 0, 0
    while n < frames:
        b = walk.positions if k % 2 == 0 else walk.positions[::-1]
        b = b if k == 0 else b[1:]  # the turning frame once
        blocks.append(b)
        n += len(b)
        k += 1
    X = np.concatenate(blocks)
    write_trc(path, MarkerTrajectories(np.arange(len(X)) / 60.0, X, walk.names,
                                       meta={"rate_hz": 60.0}))  # fmt: skip
    return len(X)


def _setup(src: Path, dst: Path, trc: str, t1: float | None, mot: str) -> None:
    """The tutorial's IK setup with another marker file, time range and output."""
    text = src.read_text()
    text = re.sub(r"<marker_file>.*?</marker_file>", f"<marker_file>{trc}</marker_file>", text)
    text = re.sub(
        r"<output_motion_file>.*?</output_motion_file>",
        f"<output_motion_file>{mot}</output_motion_file>", text,
    )  # fmt: skip
    if t1 is not None:
        text = re.sub(r"<time_range>.*?</time_range>", f"<time_range>0 {t1}</time_range>", text)
    dst.write_text(text)


def run_pair(work: Path, trc: Path, setup: Path, repeat: int, frames: int) -> dict[str, Any]:
    """OpenSim's IK tool and mocapkit (osc, ik) on one trial, whole processes."""
    mocapkit = str(Path(sys.executable).with_name("mocapkit"))
    rows: dict[str, Any] = {"frames": frames}
    times: list[float] = []
    for _ in range(repeat):
        s, _ = _timed([sys.executable, "-c", OPENSIM_RUN, setup.name], work)
        times.append(s)
    rows["opensim"] = {"best_s": min(times), "median_s": statistics.median(times)}
    for method in ("osc", "ik"):
        times, figures = [], {}
        for _ in range(repeat):
            s, out = _timed(
                [mocapkit, "markers", "reconstruct", str(trc), "--static",
                 str(GAIT / "subject01_static.trc"), "--ik-setup", str(setup), "--height-m",
                 HEIGHT, "--mass-kg", MASS, "--method", method, "-o", str(work / f"{method}.mot"),
                 "--json"], work,
            )  # fmt: skip
            times.append(s)
            figures = json.loads(out)
        rows[method] = {"best_s": min(times), "median_s": statistics.median(times), **figures}
    return rows


def c3d_methods() -> list[dict[str, Any]]:
    """Direct marker control against IK on every C3D in ../shared/data (whole trials, the
    marker set chosen as the command chooses it, limb lengths from the motion)."""
    import logging

    from mocapkit.markers.reconstruct import ReconstructionOptions, run

    logging.getLogger("mocapkit").setLevel(logging.ERROR)
    out = []
    for path in sorted((DATA / "c3d").glob("*.c3d")):
        res = {}
        for method in ("osc", "ik"):
            res[method], subject, _ = run(path, None, None, None, None,
                                          ReconstructionOptions(method=method))  # fmt: skip
        o, i = res["osc"], res["ik"]
        lo, hi = subject.human.dof_limits()
        diffs = []
        for k, c in enumerate(o.coordinate_names):
            if not o.angular[k]:
                continue
            a, b = np.degrees(o.coordinates[:, k]), np.degrees(i.coordinates[:, k])
            ok = np.isfinite(a) & np.isfinite(b)
            if ok.any():
                d = a[ok] - b[ok]
                diffs.append((float(np.sqrt(np.mean(d**2))), c, float(np.abs(d).max())))
        diffs.sort(reverse=True)
        at_limit = {}
        for name, r in res.items():
            q = r.q[:, 7:]
            at = (np.abs(q - lo) < 1e-6) | (np.abs(q - hi) < 1e-6)
            at_limit[name] = round(100.0 * float(at.any(axis=1).mean()), 1)
        sag = [c for c in ("hip_flexion_r", "knee_angle_r", "ankle_angle_r", "elbow_flex_r")
               if c in o.coordinate_names]  # fmt: skip
        sag_rms = {}
        for c in sag:
            a, b = np.degrees(o.column(c)), np.degrees(i.column(c))
            ok = np.isfinite(a) & np.isfinite(b)
            sag_rms[c] = float(np.sqrt(np.mean((a[ok] - b[ok]) ** 2))) if ok.any() else None
        out.append({
            "trial": path.name, "frames": o.n_frames, "marker_set": subject.markerset.name,
            "osc": o.metrics(), "ik": i.metrics(), "largest": diffs[:3], "sagittal": sag_rms,
            "frames_with_a_dof_at_a_limit_pct": at_limit,
        })  # fmt: skip
    return out


def render(results: dict[str, Any]) -> str:
    w, lg = results["walk"], results["long"]
    lines = [
        SECTION,
        "",
        f"Command: `.venv/bin/python -m benchmarks.markers_end_to_end --write-docs` (python "
        f"{platform.python_version()}, {os.cpu_count()} cores; load average "
        f"{results['load_before']} before, {results['load_after']} after; repeat "
        f"{results['repeat']}, long trial once). Whole processes from the command to the files "
        "written, timed from outside, side by side in this one run. OpenSim: its IK tool "
        "with the gait2392 tutorial setup (model already scaled by its Scale tool). "
        "mocapkit: `mocapkit markers reconstruct TRIAL --static subject01_static.trc "
        "--ik-setup SETUP --height-m 1.8034 --mass-kg 72.6 -o out.mot --json` (scaling "
        "included). Long trial: the walk tiled forward and backward in time.",
        "",
        "| trial | frames | tool | best s | median s | frames/s end to end | x OpenSim "
        "(best) | solve-only frames/s | marker RMS mm |",
        "|---|---:|---|---:|---:|---:|---:|---:|---:|",
    ]
    for label, r in (("gait2392 walk (0.5-2.5 s)", w), ("long walk (tiled)", lg)):
        base = r["opensim"]["best_s"]
        lines.append(
            f"| {label} | {r['frames']} | OpenSim 4.6 IK tool | {base:.2f} | "
            f"{r['opensim']['median_s']:.2f} | {r['frames'] / base:.0f} | 1.0 | - | - |"
        )
        for method, name in (("osc", "mocapkit, direct marker control"), ("ik", "mocapkit, IK")):
            m = r[method]
            lines.append(
                f"| {label} | {r['frames']} | {name} | {m['best_s']:.2f} | {m['median_s']:.2f} | "
                f"{r['frames'] / m['best_s']:.0f} | {base / m['best_s']:.1f} | "
                f"{m['solve_fps']:.0f} | {m['marker_rms_mm']:.1f} |"
            )
    lines += [
        "",
        "Direct marker control against IK on every C3D in `../shared/data/c3d` (whole trials, "
        "the marker set the command picks, limb lengths and marker places from the motion; "
        "RMS of the per-frame difference of the reported angles):",
        "",
        "| trial | frames | set | OSC / IK marker RMS mm | OSC / IK max mm | sagittal RMS "
        "OSC-IK deg | largest differences (RMS / max deg) | frames with a DOF at a limit, "
        "OSC / IK |",
        "|---|---:|---|---:|---:|---|---|---:|",
    ]
    for r in results["c3d"]:
        sag = ", ".join(f"{c} {v:.1f}" for c, v in r["sagittal"].items() if v is not None)
        big = ", ".join(f"{c} {rms:.1f} / {mx:.0f}" for rms, c, mx in r["largest"])
        lim = r["frames_with_a_dof_at_a_limit_pct"]
        lines.append(
            f"| {r['trial']} | {r['frames']} | {r['marker_set']} | {r['osc']['marker_rms_mm']} / "
            f"{r['ik']['marker_rms_mm']} | {r['osc']['marker_max_mm']} / "
            f"{r['ik']['marker_max_mm']} | {sag} | {big} | {lim['osc']} % / {lim['ik']} % |"
        )
    lines += ["", *NOTES]
    return "\n".join(lines) + "\n"


NOTES = [
    "Notes:",
    "",
    "- What a user waits for: the whole command, including Python's start, the imports "
    "(numpy, numba, Pinocchio, SciPy's BLAS for numba: ~0.7 s), loading numba's cached "
    "kernels, reading the files, scaling from the static trial, the reconstruction, the "
    "error bounds and writing the .mot. The solve-only rate is the reconstruction loop "
    "alone (`solve_fps` in `--json`); `fps` and `seconds` in `--json` are the whole command.",
    "- OpenSim's process does less: its model was scaled beforehand (the tutorial's Scale "
    "tool run, not timed); mocapkit scales from the static trial inside the timed run.",
    "- Not the same model: OpenSim fits gait2392 (23 coordinates), mocapkit its own 48-DOF "
    "skeleton (section Marker reconstruction); marker RMS is over mocapkit's 41 tracked "
    "markers here.",
    "- Direct marker control (OSC) and IK: after the fixes of issue 10 (joint limits as an "
    "active set; a step that carries the model away from its markers shortened), OSC "
    "follows IK on the C3D trials; where the reported arm angles still differ by tens of "
    "degrees, both fit the markers equally and differ in how a raised arm's rotation is "
    "split between the shoulder girdle and the shoulder (the arm_* angles of a near-"
    "gimbal pose), not in tracking.",
    '- "Frames with a DOF at a limit": direct marker control rests the spine\'s redundant '
    "DOFs at their limits more often than IK (walking2: thorax_rotation; the reported "
    "lumbar_* angles are computed over the whole spine and do not depend on the split). "
    "IK's posture prior spreads the rotation; OSC's posture task acts only in the markers' "
    "null space. Releasing such DOFs by the full solution instead of the markers' push was "
    "tried and made CMU 85_12 worse (20.2 vs 18.9 mm), so the rule stays.",
    "- Where we are short: the long trial's target was 20x OpenSim's whole process; this "
    "run's ratio is in the table. About 1.2 s of every run is fixed (Python, numpy, "
    "Pinocchio, numba and SciPy's BLAS, numba's cached kernels, the scaling), and direct "
    "marker control costs ~200 us a frame (two simulation substeps of a 48-DOF body).",
]


def write_section(text: str) -> None:
    body = DOCS.read_text()
    if SECTION in body:
        start = body.index(SECTION)
        nxt = body.find("\n## ", start + len(SECTION))
        body = body[:start] + text + ("" if nxt < 0 else body[nxt + 1 :])
    else:
        anchor = body.find("\n## Marker reconstruction through gaps")
        body = (
            (body + "\n" + text) if anchor < 0 else body[: anchor + 1] + text + body[anchor + 1 :]
        )
    DOCS.write_text(body)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs of the short trial")
    parser.add_argument("--frames", type=int, default=LONG_FRAMES, help="long trial length")
    parser.add_argument("--write-docs", action="store_true", help=f"update {DOCS.name}")
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    parser.add_argument("--skip-c3d", action="store_true", help="only the timings")
    args = parser.parse_args(argv)
    if not GAIT.is_dir():
        print(f"needs {GAIT}", file=sys.stderr)
        return 1
    try:
        import opensim  # noqa: F401
    except ImportError:
        print("needs OpenSim: make setup-bench", file=sys.stderr)
        return 1
    results: dict[str, Any] = {"load_before": _load(), "repeat": args.repeat}
    work = Path(tempfile.mkdtemp(prefix="markers_e2e_"))
    try:
        for f in ("subject01_simbody.osim", "subject01_walk1.trc", "subject01_Setup_IK.xml"):
            shutil.copy(GAIT / f, work)
        _setup(GAIT / "subject01_Setup_IK.xml", work / "walk_setup.xml", "subject01_walk1.trc",
               None, "walk_ik.mot")  # fmt: skip
        print("gait2392 walk ...", file=sys.stderr)
        results["walk"] = run_pair(work, work / "subject01_walk1.trc", work / "walk_setup.xml",
                                   args.repeat, 121)  # fmt: skip
        n = long_trial(work / "long.trc", args.frames)
        _setup(GAIT / "subject01_Setup_IK.xml", work / "long_setup.xml", "long.trc",
               (n - 1) / 60.0, "long_ik.mot")  # fmt: skip
        print(f"long trial ({n} frames) ...", file=sys.stderr)
        results["long"] = run_pair(work, work / "long.trc", work / "long_setup.xml", 1, n)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    results["load_after"] = _load()
    results["c3d"] = [] if args.skip_c3d else c3d_methods()
    text = render(results)
    print(text)
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=2, default=str))
    if args.write_docs:
        write_section(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
