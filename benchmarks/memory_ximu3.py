"""Time and peak memory of ``mocapkit imu run`` on a multi-sensor x-IMU3 export against
its length (issue 16: several sensors on their own clocks).

    python -m benchmarks.memory_ximu3 [--minutes 1 10 60] [--write-docs]

The 7-sensor x-IMU3 lower-body export in ../shared (18.6 s at 50 Hz, each sensor on its
own clock) is repeated, each sensor's ``Inertial.csv`` and ``Magnetometer.csv`` shifted by
the recording's length each time, to the length asked for, and run through ``mocapkit imu
run DIR --filter polaris -o OUT.sto`` (online, 9D) as a whole process: every sensor
filtered piece by piece into a file on disk, then all resampled onto one time base and
written a piece at a time (``mocapkit.imu.sensor_spill``). Reported: wall time and the
child's peak resident memory. Target (issue 16): within 2x from 1 min to 1 h.
``--offline``: the offline smoother instead (each sensor through files on disk).
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

from benchmarks.memory_vs_length import length_report, measure

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
EXPORT = SHARED / "ximu3-lower-body"


def _tile(src: Path, dst: Path, copies: int) -> None:
    """``src`` CSV (time stamps in us in the first column) repeated ``copies`` times,
    each copy shifted by the file's span plus one interval."""
    lines = src.read_text().splitlines()
    head, rows = lines[0], [r for r in lines[1:] if r.strip()]
    times = [int(float(r.split(",", 1)[0])) for r in rows]
    shift = times[-1] - times[0] + (times[-1] - times[-2])
    with open(dst, "w") as f:
        f.write(head + "\n")
        for k in range(copies):
            off = k * shift
            f.write("\n".join(f"{t + off}," + r.split(",", 1)[1]
                              for t, r in zip(times, rows, strict=True)) + "\n")  # fmt: skip


def long_export(
    dst: Path, minutes: float, files: tuple[str, ...] = ("Inertial.csv", "Magnetometer.csv")
) -> int:
    """The export repeated to ``minutes`` (its ``files`` per sensor); returns the copies."""
    first = next(p for p in EXPORT.iterdir() if p.is_dir())
    lines = (first / "Inertial.csv").read_text().splitlines()[1:]
    span_s = (float(lines[-1].split(",")[0]) - float(lines[0].split(",")[0])) * 1e-6
    copies = max(1, round(minutes * 60.0 / span_s))
    for sensor in (p for p in EXPORT.iterdir() if p.is_dir()):
        out = dst / sensor.name
        out.mkdir(parents=True)
        shutil.copy(sensor / "Command.json", out / "Command.json")
        for name in files:
            _tile(sensor / name, out / name, copies)
    return copies


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, nargs="+", default=[1.0, 10.0, 60.0])
    parser.add_argument("--offline", action="store_true", help="the offline smoother")
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    if not EXPORT.exists():
        raise SystemExit(f"needs {EXPORT}")
    exe = [sys.executable, "-c", "from mocapkit.cli.main import run; run()"]
    offline = ["--offline"] if args.offline else []
    rows = []
    for minutes in args.minutes:
        with tempfile.TemporaryDirectory() as d:
            src = Path(d) / "export"
            copies = long_export(src, minutes)
            m = measure([*exe, "imu", "run", str(src), "--filter", "polaris",
                         "-o", str(Path(d) / "out.sto"), *offline])  # fmt: skip
        rows.append((minutes, copies, m))
        print(minutes, copies, m, flush=True)
    lengths = " ".join(f"{x:g}" for x in args.minutes)
    length_report(
        rows, f"python -m benchmarks.memory_ximu3 --minutes {lengths}"
        + (" --offline" if args.offline else ""),
        "the 7-sensor x-IMU3 lower-body export repeated to the length, 50 Hz, each sensor on "
        "its own clock; `mocapkit imu run DIR --filter polaris"
        + (" --offline`, offline 9D" if args.offline else "`, online 9D")
        + ", whole processes",
        "Memory and time against recording length: x-IMU3 export"
        + (", offline" if args.offline else ""), args.write_docs,
        count_label="sensors x samples", count_cell=lambda c: f"7 x {c * 921}", rate=False,
    )  # fmt: skip


if __name__ == "__main__":
    main()
