"""The paper's Figures 2-4 for a marker reconstruction, plus agreement with a reference.

- Fig. 2: joint angles of the arms (shoulder, elbow, wrist per side), and the legs' sagittal
  angles (hip, knee, ankle) — over a reference ``.mot`` when one is given;
- Fig. 3: tracked (solid) versus commanded (dotted) trajectories of the paper's four markers
  (right shoulder, left wrist, left elbow, right wrist) or the first tracked ones;
- Fig. 4: per frame the margin of marker position errors (largest and smallest over the
  tracked markers) and of joint angle errors, Δq_max and Δq_min (eq. 17).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.markers.result import ReconstructionResult

ARM_COLUMNS = (
    "shoulder_flexion", "shoulder_adduction", "shoulder_rotation", "elbow_flexion",
    "pronation", "wrist_flexion",
)  # fmt: skip
LEG_COLUMNS = ("hip_flexion", "knee_angle", "ankle_angle")
PAPER_ROLES = ("right_shoulder", "left_wrist", "left_elbow", "right_wrist")


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def agreement(
    result: ReconstructionResult, reference: Path, columns: Sequence[str]
) -> dict[str, dict[str, float]]:
    """Per column: mean and RMS difference [deg] and correlation against a reference .mot,
    over the times both cover (the reference interpolated at ours)."""
    from mocapkit.io.opensim_table import read_table

    ref = read_table(reference)
    out: dict[str, dict[str, float]] = {}
    t = result.time
    sel = (t >= ref.time[0] - 1e-9) & (t <= ref.time[-1] + 1e-9)
    for c in columns:
        if c not in result.coordinate_names or c not in ref.labels:
            continue
        ours = np.degrees(result.column(c)[sel])
        theirs = np.interp(t[sel], ref.time, ref.column(c))
        # .mot files without an inDegrees line (SIMM headers) hold degrees, as OpenSim reads them
        if ref.header.get("inDegrees", "yes").lower() == "no":
            theirs = np.degrees(theirs)
        ok = np.isfinite(ours)
        if ok.sum() < 2:
            continue
        d = ours[ok] - theirs[ok]
        out[c] = {
            "mean_diff_deg": round(float(d.mean()), 2),
            "rms_diff_deg": round(float(np.sqrt((d**2).mean())), 2),
            "max_abs_diff_deg": round(float(np.abs(d).max()), 2),
            "correlation": round(float(np.corrcoef(ours[ok], theirs[ok])[0, 1]), 4),
            "frames": int(ok.sum()),
        }
    return out


def _fig2(result: ReconstructionResult, out: Path, reference: Path | None) -> Path:
    plt = _pyplot()
    ref = None
    if reference is not None:
        from mocapkit.io.opensim_table import read_table

        ref = read_table(reference)
    rows = [("arm", ARM_COLUMNS), ("leg", LEG_COLUMNS)]
    fig, axes = plt.subplots(2, 2, figsize=(12, 8), sharex=True)
    for r, (_, cols) in enumerate(rows):
        for c, side in enumerate(("r", "l")):
            ax = axes[r, c]
            for col in cols:
                name = f"{col}_{side}"
                if name in result.coordinate_names:
                    ax.plot(result.time, np.degrees(result.column(name)), label=col)
                if ref is not None and name in ref.labels:
                    ax.plot(ref.time, ref.column(name), "k:", linewidth=1)
            ax.set_title(f"{'right' if side == 'r' else 'left'} {'arm' if r == 0 else 'leg'}")
            ax.set_ylabel("angle [deg]")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7, loc="upper right")
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
        ax.set_xlim(result.time[0], result.time[-1])
    title = "Fig. 2 - joint angles from " + (
        "direct marker control" if result.method == "osc" else "least-squares IK"
    )
    fig.suptitle(title + (" (dotted: reference)" if ref is not None else ""))
    fig.tight_layout()
    path = out / "fig2_joint_angles.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _fig3(result: ReconstructionResult, out: Path, roles: Sequence[str]) -> Path:
    plt = _pyplot()
    markers = [m for m in roles if m in result.marker_names] or list(result.tracked[:4])
    fig, axes = plt.subplots(
        len(markers), 3, figsize=(12, 2.4 * len(markers)), sharex=True, squeeze=False
    )
    for i, m in enumerate(markers):
        k = result.marker_names.index(m)
        for a in range(3):
            ax = axes[i, a]
            ax.plot(result.time, result.tracked_positions[:, k, a] * 1000, "-", label="tracked")
            ax.plot(result.time, result.commanded[:, k, a] * 1000, ":", label="goal")
            ax.set_ylabel(f"{m} {'xyz'[a]} [mm]", fontsize=8)
            ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    fig.suptitle("Fig. 3 - tracked (solid) and goal (dotted) marker trajectories")
    fig.tight_layout()
    path = out / "fig3_markers.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _fig4(result: ReconstructionResult, out: Path) -> Path:
    plt = _pyplot()
    idx = [result.marker_names.index(n) for n in result.tracked]
    e = result.errors[:, idx] * 1000
    dq_max, dq_min = result.dq_extremes()
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    with np.errstate(invalid="ignore"):
        a1.plot(result.time, np.nanmax(e, axis=1), label="largest marker error")
        a1.plot(result.time, np.nanmin(e, axis=1), label="smallest marker error")
        a1.plot(result.time, result.frame_rms() * 1000, label="RMS", linewidth=1)
    a1.set_ylabel("marker error [mm]")
    a1.legend(fontsize=8)
    a1.grid(alpha=0.3)
    a2.plot(result.time, np.degrees(dq_max), label="Δq_max (eq. 17)")
    a2.plot(result.time, np.degrees(dq_min), label="Δq_min (eq. 17)")
    a2.set_ylabel("joint angle error bound [deg]")
    a2.set_xlabel("time [s]")
    a2.legend(fontsize=8)
    a2.grid(alpha=0.3)
    fig.suptitle("Fig. 4 - margins of marker position errors and joint angle errors")
    fig.tight_layout()
    path = out / "fig4_margins.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_report(
    result: ReconstructionResult,
    out_dir: str | Path,
    reference: str | Path | None = None,
    paper_markers: Sequence[str] = (),
) -> dict[str, Any]:
    """Write the figures and ``report.json`` into ``out_dir``; returns the JSON content."""
    import json

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ref = Path(reference) if reference is not None else None
    roles = list(paper_markers) or [m for level in result.levels[:2] for m in level][:4]
    figures = [_fig2(result, out, ref), _fig3(result, out, roles), _fig4(result, out)]
    dq_max, dq_min = result.dq_extremes()
    summary: dict[str, Any] = {
        "metrics": result.metrics(),
        "method": result.method,
        "mode": result.mode,
        "levels": result.levels,
        "joint_error_bound_deg": {
            "max_of_max": round(float(np.degrees(dq_max.max())), 3),
            "min_of_min": round(float(np.degrees(dq_min.min())), 3),
        },
        "figures": [p.name for p in figures],
        "warnings": list(result.warnings),
        "meta": result.meta,
    }
    if ref is not None:
        cols = [f"{c}_{s}" for c in LEG_COLUMNS for s in ("r", "l")]
        summary["agreement_with_reference"] = agreement(result, ref, cols)
    (out / "report.json").write_text(json.dumps(summary, indent=2, default=str))
    return summary
