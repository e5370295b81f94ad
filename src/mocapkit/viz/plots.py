"""Report plots: matplotlib ``Figure`` objects (no pyplot), degrees and millimetres at
the edge. Each function takes plain arrays (time first) and returns one figure."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from mocapkit._validate import FloatArray


def joint_angles_figure(
    time: Any,
    names: Sequence[str],
    values_rad: Any,
    truth_rad: Any = None,
    title: str = "Joint angles",
    truth_label: str = "truth",
) -> Figure:
    """One panel per coordinate: angles [deg] over time [s], optionally against a truth."""
    t = np.asarray(time, dtype=float)
    v = np.degrees(np.asarray(values_rad, dtype=float))
    tr = None if truth_rad is None else np.degrees(np.asarray(truth_rad, dtype=float))
    k = len(names)
    cols = min(3, k)
    rows = (k + cols - 1) // cols
    fig = Figure(figsize=(4.2 * cols, 2.4 * rows + 0.6))
    axes = fig.subplots(rows, cols, squeeze=False)
    for i, name in enumerate(names):
        ax = axes.flat[i]
        if tr is not None:
            ax.plot(t, tr[:, i], color="0.6", lw=2.5, label=truth_label)
        ax.plot(t, v[:, i], color="C0", lw=1.2, label="mocapkit")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("time [s]", fontsize=8)
        ax.set_ylabel("[deg]", fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[k:]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7, loc="best")
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def ee_paths_figure(
    cmd_time: Any,
    cmd: Any,
    ach_time: Any,
    ach: Any,
    truth: Any = None,
    title: str = "End effector: commanded and achieved (chest frame)",
) -> Figure:
    """Fig. 9 of the paper: the y-z path (left) and each axis over time (right) [mm]."""
    tc, c = np.asarray(cmd_time, float), 1e3 * np.asarray(cmd, float)
    ta, a = np.asarray(ach_time, float), 1e3 * np.asarray(ach, float)
    tr = None if truth is None else 1e3 * np.asarray(truth, float)
    fig = Figure(figsize=(12, 4.6))
    left, right = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1, 1.6]})
    if tr is not None:
        left.plot(tr[:, 1], tr[:, 2], color="0.6", lw=3, label="truth command")
    left.plot(c[:, 1], c[:, 2], "g-", lw=1.2, label="commanded")
    if len(ta):
        sel = (ta >= tc[0]) & (ta <= tc[-1]) if len(tc) else slice(None)
        left.plot(a[sel, 1], a[sel, 2], "b-", lw=1.0, label="achieved")
    left.set_xlabel("chest y [mm]")
    left.set_ylabel("chest z [mm]")
    left.set_aspect("equal", adjustable="datalim")
    left.legend(fontsize=8)
    for k, axis in enumerate("xyz"):
        right.plot(tc, c[:, k], color=f"C{k}", lw=1.4, label=f"{axis} commanded")
        if len(ta):
            right.plot(ta, a[:, k], color=f"C{k}", lw=0.8, ls="--", label=f"{axis} achieved")
    right.set_xlabel("time [s]")
    right.set_ylabel("position [mm]")
    right.legend(fontsize=7, ncol=3)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def filter_errors_figure(
    times: Mapping[str, FloatArray], errors_deg: Mapping[str, FloatArray], title: str
) -> Figure:
    """Orientation error [deg] of each sensor's filter over time [s]."""
    fig = Figure(figsize=(10, 3.4))
    ax = fig.subplots()
    for name, err in errors_deg.items():
        ax.plot(times[name], err, lw=0.9, label=name)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("orientation error [deg]")
    ax.legend(fontsize=8)
    ax.set_title(title)
    fig.tight_layout()
    return fig


def imu_errors_figure(rows: Sequence[Mapping[str, Any]], title: str) -> Figure:
    """Bars of total / heading / inclination RMSE [deg] per filter and mode."""
    labels = [f"{r['filter']} {r['mode']}" for r in rows]
    keys = ("total_deg", "heading_deg", "inclination_deg")
    x = np.arange(len(rows))
    fig = Figure(figsize=(8, 3.4))
    ax = fig.subplots()
    for i, key in enumerate(keys):
        ax.bar(x + (i - 1) * 0.27, [r[key] for r in rows], 0.27, label=key.replace("_deg", ""))
    ax.set_xticks(x, labels, fontsize=8)
    ax.set_ylabel("RMSE [deg]")
    ax.legend(fontsize=8)
    ax.set_title(title)
    fig.tight_layout()
    return fig


def marker_residuals_figure(
    time: Any, residual_m: Any, marker_names: Sequence[str], title: str
) -> Figure:
    """Per-frame marker residuals: RMS and maximum over the visible markers against time
    (left), mean residual per marker (right) [mm]. NaN residuals (hidden markers) are
    left out."""
    t = np.asarray(time, float)
    r = 1e3 * np.asarray(residual_m, float)
    vis = np.isfinite(r)
    rr = np.where(vis, r, 0.0)
    n = np.maximum(vis.sum(axis=1), 1)
    rms = np.sqrt((rr**2).sum(axis=1) / n)
    mx = np.where(vis, r, -np.inf).max(axis=1)
    fig = Figure(figsize=(12, 4.0))
    left, right = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.3, 1]})
    left.plot(t, rms, label="RMS over visible markers")
    left.plot(t, np.where(np.isfinite(mx), mx, np.nan), lw=0.8, label="maximum")
    left.set_xlabel("time [s]")
    left.set_ylabel("residual [mm]")
    left.legend(fontsize=8)
    means = np.array(
        [np.nanmean(r[:, j]) if vis[:, j].any() else np.nan for j in range(r.shape[1])]
    )
    order = np.argsort(np.nan_to_num(means, nan=-1.0))[::-1]
    right.barh(np.arange(len(order)), means[order], color="C2")
    right.set_yticks(np.arange(len(order)), [marker_names[j] for j in order], fontsize=6)
    right.invert_yaxis()
    right.set_xlabel("mean residual [mm]")
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def latency_figure(latency_ms: Any, title: str) -> Figure:
    """Histogram of the host-side pipeline latency [ms], with p50 and p99 marked."""
    lat = np.asarray(latency_ms, float)
    lat = lat[np.isfinite(lat)]
    fig = Figure(figsize=(7, 3.0))
    ax = fig.subplots()
    if len(lat):
        ax.hist(lat, bins=60, color="C0")
        for q, ls in ((50, "-"), (99, "--")):
            v = float(np.percentile(lat, q))
            ax.axvline(v, color="k", ls=ls, lw=1, label=f"p{q} {v:.2f} ms")
        ax.legend(fontsize=8)
    ax.set_xlabel("packet arrival to robot command sent [ms]")
    ax.set_ylabel("packets")
    ax.set_title(title)
    fig.tight_layout()
    return fig
