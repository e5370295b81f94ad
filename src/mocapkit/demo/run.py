"""The demo, end to end on bundled data: teleoperation from a simulated suit, a real
marker trial, the orientation filters on a real recording, then one HTML report."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mocapkit.demo.progress import Progress, no_progress
from mocapkit.errors import ConfigError
from mocapkit.teleop.operator import SHAPES
from mocapkit.viz.report import HtmlReport

SECTIONS = ("teleop", "markers", "retarget", "imu")


@dataclass(frozen=True)
class DemoConfig:
    """Attributes:
    out_dir: where the report and the outputs go.
    shape: the shape the simulated operator traces.
    shape_s: its duration [s] (the teleoperation runs in real time: about shape_s + 7 s).
    sections: which sections to run (all by default).
    seed: sensor noise and mounting seed.
    """

    out_dir: Path = Path("mocapkit-demo")
    shape: str = "infinity"
    shape_s: float = 6.0
    sections: tuple[str, ...] = SECTIONS
    seed: int = 0

    def __post_init__(self) -> None:
        if self.shape not in SHAPES:
            raise ConfigError(f"shape: expected one of {', '.join(SHAPES)}, got {self.shape!r}")
        unknown = [s for s in self.sections if s not in SECTIONS]
        if unknown or not self.sections:
            raise ConfigError(
                f"sections: expected some of {', '.join(SECTIONS)}, got {list(self.sections)}"
            )
        if not 1.0 <= self.shape_s <= 60.0:
            raise ConfigError(f"shape_s: expected 1-60 s, got {self.shape_s}")


@dataclass
class DemoResult:
    report: Path
    outputs: dict[str, Path] = field(default_factory=dict)
    summary: dict[str, Any] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)


def run_demo(config: DemoConfig | None = None, progress: Progress = no_progress) -> DemoResult:
    """Run the sections, write ``report.html`` and the outputs into ``config.out_dir``."""
    from mocapkit.demo.imu_section import report_imu, run_imu
    from mocapkit.demo.markers_section import markers_summary, report_markers, run_markers
    from mocapkit.demo.teleop_section import (
        report_teleop,
        run_teleop,
        teleop_summary,
        write_teleop_outputs,
    )

    c = config or DemoConfig()
    out = Path(c.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report = HtmlReport(
        "mocapkit demo",
        "Human motion capture to robot commands, end to end on data bundled with mocapkit: "
        "a simulated inertial suit teleoperating Robonaut 2's arm through the live chain, a "
        "real optical marker trial reconstructed and retargeted onto the Unitree G1 humanoid, "
        "and the orientation filters on a real IMU recording.",
    )
    result = DemoResult(report=out / "report.html")
    clock = time.perf_counter
    if "teleop" in c.sections:
        t0 = clock()
        r = run_teleop(c.shape, c.shape_s, c.seed, progress)
        result.summary["teleop"] = summary = teleop_summary(r, c.shape)
        result.outputs.update(write_teleop_outputs(r, out))
        report_teleop(report, r, summary)
        result.seconds["teleop"] = clock() - t0
    if "markers" in c.sections:
        t0 = clock()
        markers = run_markers(out, progress)
        result.summary["markers"] = markers_summary(markers)
        result.outputs.update(markers.get("outputs", {}))
        report_markers(report, markers)
        result.seconds["markers"] = clock() - t0
    if "retarget" in c.sections:
        from mocapkit.demo.retarget_section import (
            report_retarget,
            retarget_summary,
            run_retarget,
        )

        t0 = clock()
        rt = run_retarget(out, progress)
        result.summary["retarget"] = retarget_summary(rt)
        result.outputs.update(rt.get("outputs", {}))
        report_retarget(report, rt)
        result.seconds["retarget"] = clock() - t0
    if "imu" in c.sections:
        t0 = clock()
        result.summary["imu"] = imu = run_imu(progress)
        report_imu(report, imu)
        result.seconds["imu"] = clock() - t0
    t0 = clock()
    progress("report", 0, 1)
    report.write(result.report)
    progress("report", 1, 1)
    result.seconds["report"] = clock() - t0
    return result
