"""Demo section: a real optical marker trial reconstructed (OpenSim's gait2392 subject01).

The bundled walking trial (2.5 s, 41 markers) and a 1 s crop of its static trial go
through ``mocapkit.markers`` (scaling from the static trial, then direct marker control
and the least-squares IK baseline). When the marker package is not installed in this
build, the section says so and the rest of the demo runs.
"""

from __future__ import annotations

import importlib.util
import logging
from contextlib import ExitStack
from dataclasses import dataclass, field
from importlib.resources import as_file, files
from pathlib import Path
from typing import Any, Literal

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.demo.progress import Progress, no_progress
from mocapkit.viz.plots import joint_angles_figure, marker_residuals_figure
from mocapkit.viz.report import HtmlReport

WALK = "subject01_walk1.trc"
# the tutorial subject's, from OpenSim's subject01_Setup_Scale.xml (a user passes
# --height-m / --mass-kg; the demo knows them, so it asks nothing it cannot act on)
SUBJECT_HEIGHT_M = 1.8034
SUBJECT_MASS_KG = 72.6
STATIC = "subject01_static_crop.trc"
SAGITTAL = ("hip_flexion_r", "knee_angle_r", "ankle_angle_r", "hip_flexion_l", "knee_angle_l")


def bundled_marker_files(stack: ExitStack) -> tuple[Path, Path]:
    """Paths of the bundled walking and static trials (valid while ``stack`` is open)."""
    root = files("mocapkit") / "data" / "gait2392"
    return (
        stack.enter_context(as_file(root / WALK)),
        stack.enter_context(as_file(root / STATIC)),
    )


def markers_available() -> bool:
    try:
        return importlib.util.find_spec("mocapkit.markers.reconstruct") is not None
    except ModuleNotFoundError:  # no mocapkit.markers package at all
        return False


@dataclass
class MarkerOutcome:
    """One reconstruction: figures, joint angles and residuals (time first)."""

    method: str
    figures: dict[str, Any]
    time: FloatArray
    coordinate_names: tuple[str, ...]
    coordinates: FloatArray  # (N, k) [rad] (translations [m])
    marker_names: tuple[str, ...]
    residual_m: FloatArray  # (N, M), NaN for hidden markers
    warnings: list[str] = field(default_factory=list)


def run_markers(
    out_dir: Path,
    progress: Progress = no_progress,
    methods: tuple[Literal["osc", "ik"], ...] = ("osc", "ik"),
) -> dict[str, Any]:
    """Reconstruct the bundled trial by direct marker control and by IK (``methods``).

    Returns ``{"status": "ok", "outcomes": [MarkerOutcome, ...], "outputs": {...}}``, or
    ``{"status": "unavailable", "reason": ...}`` when ``mocapkit.markers`` is absent.
    """
    if not markers_available():
        return {
            "status": "unavailable",
            "reason": "mocapkit.markers (marker reconstruction) is not part of this build",
        }
    from mocapkit.markers.reconstruct import ReconstructionOptions, run

    out_dir.mkdir(parents=True, exist_ok=True)
    outcomes = []
    outputs: dict[str, Path] = {}
    with ExitStack() as stack:
        walk, static = bundled_marker_files(stack)
        # what the reconstruction leaves out comes back in result.warnings and goes into
        # the report, not onto the terminal (nothing there the demo's user could act on)
        quiet = logging.getLogger("mocapkit.markers")
        stack.callback(quiet.setLevel, quiet.level)
        quiet.setLevel(logging.ERROR)
        for i, method in enumerate(methods):
            progress("marker reconstruction", i, len(methods))
            result, _subject, _cleaning = run(
                walk, static, None, SUBJECT_HEIGHT_M, SUBJECT_MASS_KG,
                ReconstructionOptions(method=method),
            )  # fmt: skip
            outputs[f"markers_{method}_mot"] = result.write_mot(out_dir / f"walk1_{method}.mot")
            outcomes.append(
                MarkerOutcome(
                    method,
                    result.metrics(),
                    np.asarray(result.time),
                    tuple(result.coordinate_names),
                    np.asarray(result.coordinates),
                    tuple(result.marker_names),
                    np.asarray(result.errors),
                    list(result.warnings),
                )
            )
        progress("marker reconstruction", len(methods), len(methods))
    return {"status": "ok", "outcomes": outcomes, "outputs": outputs}


def markers_summary(markers: dict[str, Any]) -> dict[str, Any]:
    if markers["status"] != "ok":
        return {"status": markers["status"], "reason": markers["reason"]}
    return {"status": "ok", **{o.method: o.figures for o in markers["outcomes"]}}


def report_markers(report: HtmlReport, markers: dict[str, Any]) -> None:
    sec = report.section(
        "Marker reconstruction of a real walking trial",
        "OpenSim's gait2392 tutorial subject01 (bundled: the 2.5 s walking trial, 41 markers "
        "at 60 Hz, and 1 s of the static trial for scaling). Direct marker control (the "
        "prioritized operational-space tracking of the second seed paper) against the "
        "least-squares IK baseline on the same scaled model.",
    )
    if markers["status"] != "ok":
        sec.note(f"Not run: {markers['reason']}.")
        return
    outcomes: list[MarkerOutcome] = markers["outcomes"]
    keys = list(outcomes[0].figures)
    sec.table(["method", *keys], [[o.method, *(o.figures[k] for k in keys)] for o in outcomes])
    for o in outcomes:
        sec.figure(
            marker_residuals_figure(
                o.time, o.residual_m, o.marker_names, f"Marker residuals ({o.method})"
            ),
            f"Marker residuals, {o.method}",
        )
    o = outcomes[0]
    names = [n for n in SAGITTAL if n in o.coordinate_names]
    if names:
        cols = [o.coordinate_names.index(n) for n in names]
        other = outcomes[1] if len(outcomes) > 1 else None
        truth = None
        if other is not None and all(n in other.coordinate_names for n in names):
            truth = other.coordinates[:, [other.coordinate_names.index(n) for n in names]]
        sec.figure(
            joint_angles_figure(
                o.time, names, o.coordinates[:, cols], truth,
                f"Sagittal joint angles: {o.method} (blue) and ik (grey)", truth_label="ik",
            ),
            "Sagittal joint angles of the walking trial",
        )  # fmt: skip
    for o in outcomes:
        for w in o.warnings:
            sec.note(f"{o.method}: {w}")
