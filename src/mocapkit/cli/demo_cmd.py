"""``mocapkit demo``: the whole pipeline on bundled data, ending with an HTML report.
Works without ../shared (everything it reads ships with mocapkit)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from mocapkit.cli.common import EXIT_OK, StepProgress, print_json

_EXAMPLES = """\
examples:
  mocapkit demo                              # everything; prints the report's path
  mocapkit demo -o /tmp/demo --shape circle
  mocapkit demo --sections imu --json        # only the orientation filters, as JSON
  mocapkit demo --warm-up                    # compile the kernels once (make setup does)

Sections: teleop (a simulated suit streams over loopback UDP through the receiver,
filters, body model, Robonaut-arm retargeting and the robot-server process, in real
time), markers (a real optical marker trial reconstructed), retarget (the same trial
onto the Unitree G1 humanoid: figures and its trajectory), imu (every orientation filter
on a real BROAD recording). Outputs in --out: report.html, the body model's joint angles
(.mot), a Foxglove MCAP of the session, the marker joint angles (.mot), G1's trajectory
(walk1_g1.npz: mocapkit view walk1_g1.npz).
"""


def register(sub: Any) -> None:
    from mocapkit.demo.run import SECTIONS
    from mocapkit.teleop.operator import SHAPES

    demo = sub.add_parser(
        "demo",
        help="run the whole pipeline on bundled data and write an HTML report",
        description="The main job, on data bundled with mocapkit (no download, no ../shared): "
        "teleoperation of Robonaut 2's arm from a simulated suit through the live chain, a "
        "real marker trial reconstructed, the orientation filters on a real recording. Ends "
        "by writing an HTML report and printing its path.",
        epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    demo.add_argument(
        "-o", "--output", "--out", dest="out", type=Path, default=Path("mocapkit-demo"),
        help="output folder",
    )  # fmt: skip
    demo.add_argument("--shape", default="infinity", choices=SHAPES, help="operator's shape")
    demo.add_argument(
        "--shape-seconds", type=float, default=6.0, help="duration of the shape [s] (1-60)"
    )
    demo.add_argument(
        "--sections",
        default=",".join(SECTIONS),
        help=f"comma-separated subset of {','.join(SECTIONS)}",
    )
    demo.add_argument("--seed", type=int, default=0, help="sensor noise and mounting seed")
    demo.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    demo.add_argument("--no-progress", action="store_true", help="no progress bars")
    demo.add_argument(
        "--warm-up",
        action="store_true",
        help="only compile the numba kernels the demo uses (2 processes), then exit: a "
        "machine's first demo otherwise spends about a minute compiling",
    )
    demo.set_defaults(func=_demo)


def _warm_up(args: argparse.Namespace) -> int:
    from mocapkit.demo.warm_up import warm_up

    def done(task: str, seconds: float) -> None:
        if not args.json:
            print(f"warm-up: {task} ready in {seconds:.1f} s", file=sys.stderr)

    seconds = warm_up(on_done=done)
    if args.json:
        print_json({"warm_up_seconds": seconds})
    return EXIT_OK


def _demo(args: argparse.Namespace) -> int:
    if args.warm_up:
        return _warm_up(args)
    from mocapkit.demo.run import DemoConfig, run_demo

    cfg = DemoConfig(
        out_dir=args.out,
        shape=args.shape,
        shape_s=args.shape_seconds,
        sections=tuple(s.strip() for s in args.sections.split(",") if s.strip()),
        seed=args.seed,
    )
    with StepProgress(enabled=not args.no_progress) as bars:
        result = run_demo(cfg, bars)
    summary = {
        "report": str(result.report),
        "outputs": {k: str(v) for k, v in result.outputs.items()},
        "seconds": result.seconds,
        **result.summary,
    }
    if args.json:
        print_json(summary)
        return EXIT_OK
    _print_text(summary)
    return EXIT_OK


def _fmt(v: Any, unit: str = "") -> str:
    return "n/a" if v is None else f"{v:.2f}{unit}"


def _print_text(s: dict[str, Any]) -> None:
    out = sys.stdout
    out.write("mocapkit demo\n")
    if "teleop" in s:
        t = s["teleop"]
        out.write(
            f"\nteleoperation ({t['shape']}, simulated suit -> UDP -> receiver -> {t['filter']} "
            "-> body model -> Robonaut 2 -> robot server)\n"
            f"  end effector vs truth {_fmt(t['ee_rmse_mm'], ' mm')} RMSE; robot lag "
            f"{_fmt(t['robot_lag_ms'], ' ms')}; pipeline p50 {_fmt(t['pipeline_ms_p50'], ' ms')}, "
            f"p99 {_fmt(t['pipeline_ms_p99'], ' ms')}\n"
        )
        joints = ", ".join(f"{k} {v:.1f}" for k, v in t["joint_rmse_deg"].items())
        out.write(f"  joint angles vs the simulated operator [deg RMSE]: {joints}\n")
    if "markers" in s:
        m = s["markers"]
        out.write("\nmarker reconstruction (gait2392 subject01 walk)\n")
        if m["status"] != "ok":
            out.write(f"  not run: {m['reason']}\n")
        for method in ("osc", "ik"):
            if method in m:
                f = m[method]
                out.write(
                    f"  {method}: {f['frames']} frames, solved at {f['solve_fps']:.0f} frames/s, "
                    f"marker RMS {f['marker_rms_mm']:.1f} mm (max {f['marker_max_mm']:.1f} mm)\n"
                )
    if "imu" in s:
        out.write("\norientation filters on BROAD trial 07 (crop), RMSE [deg]\n")
        out.write("  filter     mode   total  heading   incl.   samples/s\n")
        for r in s["imu"]["results"]:
            out.write(
                f"  {r['filter']:10s} {r['mode']:4s} {r['total_deg']:7.2f} {r['heading_deg']:8.2f} "
                f"{r['inclination_deg']:7.2f} {r['samples_per_s']:11,.0f}\n"
            )
    secs = ", ".join(f"{k} {v:.1f} s" for k, v in s["seconds"].items())
    out.write(f"\ntimes: {secs}\nreport: {s['report']}\n")
