"""Time and peak memory of ``mocapkit imu run`` and ``mocapkit body angles`` on Xsens MT
Manager exports against their length (issue 16).

    python -m benchmarks.memory_xsens [--minutes 1 10 60] [--write-docs]

OpenSense's Xsens walk in ../shared (8 exports, 100 Hz, ~25 s, the devices' orientation
matrices and accelerometers) is tiled to the length asked for, each export's packet
counter continued (it wraps at 65,536 as the device's does), and run through ``mocapkit
imu run DIR --filter device -o OUT.sto`` and ``mocapkit body angles DIR --preset
opensense --map ...`` (the exports' sensors as OpenSense's myIMUMappings.xml names them)
as whole processes: each export read block by block (one pass for the packets the
exports share, one for the data), the sensors spilled to disk, aligned and written a
piece at a time. Reported: wall time and the child's peak resident memory. Target
(issue 16): within 2x from 1 min to 1 h.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from benchmarks.memory_vs_length import length_report, measure

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
EXPORTS = SHARED / "opensense" / "xsens" / "IMUData"
MAP = {"torso": "00B42268", "pelvis": "00B42279", "tibia_r": "00B4227D", "femur_r": "00B4227C",
       "tibia_l": "00B421ED", "femur_l": "00B421EE", "calcn_r": "00B421EF",
       "calcn_l": "00B421E6"}  # fmt: skip


def long_exports(dst: Path, minutes: float) -> int:
    """Every export tiled to ``minutes``, its counter continued; returns the rows each."""
    dst.mkdir(parents=True)
    rows_out = 0
    for src in sorted(EXPORTS.glob("MT_*.txt")):
        lines = src.read_text().splitlines()
        k = next(i for i, ln in enumerate(lines) if not ln.startswith("//"))
        head, data = lines[: k + 1], [ln for ln in lines[k + 1 :] if ln.strip()]
        cells = [ln.split("\t", 1) for ln in data]
        first = int(cells[0][0])
        n = round(minutes * 60 * 100)
        with open(dst / src.name, "w") as f:
            f.write("\n".join(head) + "\n")
            for i in range(n):
                f.write(f"{(first + i) % 65536}\t{cells[i % len(cells)][1]}\n")
        rows_out = n
    return rows_out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, nargs="+", default=[1.0, 10.0, 60.0])
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    if not EXPORTS.exists():
        raise SystemExit(f"needs {EXPORTS}")
    exe = [sys.executable, "-c", "from mocapkit.cli.main import run; run()"]
    maps = [a for k, v in MAP.items() for a in ("--map", f"{k}={v}")]
    rows: dict[str, list] = {"imu": [], "body": []}  # type: ignore[type-arg]
    for minutes in args.minutes:
        with tempfile.TemporaryDirectory() as d:
            src = Path(d) / "IMUData"
            n = long_exports(src, minutes)
            for what, argv in (
                ("imu", ["imu", "run", str(src), "--filter", "device", "-o", f"{d}/o.sto"]),
                ("body", ["body", "angles", str(src), "--preset", "opensense", *maps,
                          "-o", f"{d}/o.mot"]),
            ):  # fmt: skip
                m = measure([*exe, *argv])
                rows[what].append((minutes, n, m))
                print(what, minutes, n, m, flush=True)
    lengths = " ".join(f"{x:g}" for x in args.minutes)
    for what, title, command in (
        ("imu", "`mocapkit imu run DIR --filter device`", "imu run"),
        ("body", "`mocapkit body angles DIR --preset opensense --map ...`", "body angles"),
    ):
        length_report(
            rows[what], f"python -m benchmarks.memory_xsens --minutes {lengths}",
            f"OpenSense's 8 Xsens exports tiled to the length, 100 Hz; {title}, whole "
            "processes", f"Memory and time against recording length: Xsens exports, {command}",
            args.write_docs, count_label="sensors x samples", count_cell=lambda c: f"8 x {c}",
            rate=False,
        )  # fmt: skip


if __name__ == "__main__":
    main()
