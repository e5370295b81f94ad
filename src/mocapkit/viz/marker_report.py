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

from mocapkit._validate import FloatArray
from mocapkit.markers.result import ReconstructionResult

ARM_COLUMNS = ("arm_flex", "arm_add", "arm_rot", "elbow_flex", "pro_sup", "wrist_flex")
LEG_COLUMNS = ("hip_flexion", "knee_angle", "ankle_angle")
PAPER_ROLES = ("right_shoulder", "left_wrist", "left_elbow", "right_wrist")


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def read_reference(reference: Path, model: str = "auto") -> tuple[Any, FloatArray, str]:
    """A reference ``.mot`` (degrees) in our coordinate senses: the table, its values (N, K)
    [deg] and the convention it came in (gait2392's knee sign is flipped; see
    :func:`mocapkit.markers.coordinates.to_rajagopal`)."""
    from mocapkit.io.opensim_table import read_table
    from mocapkit.markers.coordinates import to_rajagopal

    ref = read_table(reference)
    data = np.column_stack([ref.column(c) for c in ref.labels])
    # .mot files without an inDegrees line (SIMM headers) hold degrees, as OpenSim reads them
    if ref.header.get("inDegrees", "yes").lower() == "no":
        data = np.degrees(data)
    values, used = to_rajagopal(ref.labels, data, model)
    return ref, values, used


def agreement(
    result: ReconstructionResult,
    reference: Path,
    columns: Sequence[str],
    reference_model: str = "auto",
) -> dict[str, dict[str, float]]:
    """Per column: mean and RMS difference [deg] and correlation against a reference .mot,
    over the times both cover (the reference interpolated at ours), after bringing the
    reference to our senses (``reference_model``: auto, gait2392 or rajagopal)."""
    ref, values, _ = read_reference(reference, reference_model)
    out: dict[str, dict[str, float]] = {}
    t = result.time
    sel = (t >= ref.time[0] - 1e-9) & (t <= ref.time[-1] + 1e-9)
    for c in columns:
        if c not in result.coordinate_names or c not in ref.labels:
            continue
        ours = np.degrees(result.column(c)[sel])
        theirs = np.interp(t[sel], ref.time, values[:, ref.labels.index(c)])
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


def _fig2(
    result: ReconstructionResult, out: Path, reference: Path | None, reference_model: str
) -> Path:
    plt = _pyplot()
    ref = None
    if reference is not None:
        ref, ref_values, _ = read_reference(reference, reference_model)
    rows = [("arm", ARM_COLUMNS), ("leg", LEG_COLUMNS)]
    fig, axes = plt.subplots(2, 2, figsize=(12, 8), sharex=True)
    for r, (_, cols) in enumerate(rows):
        for c, side in enumerate(("r", "l")):
            ax = axes[r, c]
            for col in cols:
                name = f"{col}_{side}"
                if name in result.coordinate_names:
                    values = result.column(name)
                    gaps = int(np.isnan(values).sum())
                    label = f"{col} (undetermined in {gaps} frames)" if gaps else col
                    ax.plot(result.time, np.degrees(values), label=label)
                if ref is not None and name in ref.labels:
                    ax.plot(ref.time, ref_values[:, ref.labels.index(name)], "k:", linewidth=1)
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


def _shade_blind(ax: Any, result: ReconstructionResult) -> bool:
    """Grey spans over frames without any visible tracked marker; True if there are any."""
    blind = result.visible_count() == 0
    if not blind.any():
        return False
    t = result.time
    edges = np.flatnonzero(np.diff(np.concatenate([[0], blind.astype(int), [0]])))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        ax.axvspan(t[a], t[b - 1], color="0.85", linewidth=0)
    return True


def _fig4(result: ReconstructionResult, out: Path) -> Path:
    """Margins per frame; frames without a visible marker are grey spans (no value there),
    never a silent gap in a line."""
    plt = _pyplot()
    idx = [result.marker_names.index(n) for n in result.tracked]
    e = result.errors[:, idx] * 1000
    seen = np.isfinite(e).any(axis=1)
    e_max = np.full(len(e), np.nan)
    e_min = np.full(len(e), np.nan)
    e_max[seen] = np.max(np.where(np.isfinite(e[seen]), e[seen], -np.inf), axis=1)
    e_min[seen] = np.min(np.where(np.isfinite(e[seen]), e[seen], np.inf), axis=1)
    dq_max, dq_min = result.dq_extremes()
    fig, (a1, a2, a3) = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    a1.plot(result.time, e_max, label="largest marker error")
    a1.plot(result.time, e_min, label="smallest marker error")
    a1.plot(result.time, result.frame_rms() * 1000, label="RMS", linewidth=1)
    a1.set_ylabel("marker error [mm]")
    a2.plot(result.time, np.degrees(dq_max), label="Δq_max (eq. 17)")
    a2.plot(result.time, np.degrees(dq_min), label="Δq_min (eq. 17)")
    a2.set_ylabel("joint angle error bound [deg]")
    if result.bound is not None:
        a3.semilogy(
            result.time, result.bound.worst_sensitivity_deg_per_mm, label="least determined DOF"
        )
    a3.set_ylabel("conditioning [deg per mm]")
    a3.set_xlabel("time [s]")
    blind = False
    for ax in (a1, a2, a3):
        blind = _shade_blind(ax, result)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    title = "Fig. 4 - margins of marker position errors and joint angle errors"
    note = "\n(grey: no visible tracked marker, nothing to measure)" if blind else ""
    fig.suptitle(title + note)
    fig.tight_layout()
    path = out / "fig4_margins.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _rounded_deg(x: FloatArray, reduce: Any) -> float | None:
    ok = np.isfinite(x)
    return round(float(np.degrees(reduce(x[ok]))), 3) if ok.any() else None


def write_report(
    result: ReconstructionResult,
    out_dir: str | Path,
    reference: str | Path | None = None,
    paper_markers: Sequence[str] = (),
    reference_model: str = "auto",
) -> dict[str, Any]:
    """Write the figures and ``report.json`` into ``out_dir``; returns the JSON content."""
    import json

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ref = Path(reference) if reference is not None else None
    roles = list(paper_markers) or [m for level in result.levels[:2] for m in level][:4]
    figures = [
        _fig2(result, out, ref, reference_model),
        _fig3(result, out, roles),
        _fig4(result, out),
    ]
    dq_max, dq_min = result.dq_extremes()
    blind = result.visible_count() == 0
    summary: dict[str, Any] = {
        "metrics": result.metrics(),
        "method": result.method,
        "mode": result.mode,
        "levels": result.levels,
        "joint_error_bound_deg": {
            "max_of_max": _rounded_deg(dq_max, np.max),
            "min_of_min": _rounded_deg(dq_min, np.min),
            "frames_capped_at_joint_range": (
                int(result.bound.capped.any(axis=1).sum()) if result.bound else 0
            ),
            "poorly_determined_frames": dict(result.bound.poorly_determined)
            if result.bound
            else {},
        },
        "frames_without_visible_marker": int(blind.sum()),
        "figures": [p.name for p in figures],
        "warnings": list(result.warnings),
        "meta": {k: v for k, v in result.meta.items() if k != "c3d"},
    }
    if ref is not None:
        cols = [f"{c}_{s}" for c in LEG_COLUMNS for s in ("r", "l")]
        summary["agreement_with_reference"] = agreement(result, ref, cols, reference_model)
        summary["reference_convention"] = read_reference(ref, reference_model)[2]
    (out / "report.json").write_text(json.dumps(summary, indent=2, default=str))
    return summary
