"""What a reconstruction returns: joint angles, tracked versus commanded markers, errors and
the paper's per-frame joint-error bounds (eq. 14-17), with writers for .mot, CSV and TRC.

Coordinates that no visible marker determines (structurally: no tracked marker visible on
the segment the DOF moves or below it, and no coordinate task holding it) are NaN in those
frames; a column that is never determined is dropped from the files, with a warning.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.human_model import HumanModel
from mocapkit.markers.coordinates import angular_columns, coordinate_names, coordinates_from_q
from mocapkit.markers.kinematics import MarkerKinematics

log = logging.getLogger(__name__)


def joint_error_bounds(
    human: HumanModel,
    names: Sequence[str],
    Q: FloatArray,
    X: FloatArray,
    weights: FloatArray,
    locked: Sequence[str] = (),
) -> FloatArray:
    """Eq. 15 for IK solutions: Δq = A⁻¹ Jᵀ (J A⁻¹ Jᵀ)⁺ Δx per frame (J: the weighted marker
    rows at the solution, Δx their residuals, below the locked coordinates as for direct
    marker control), computed with the same kernel as the OSC's."""
    from mocapkit.markers import rigid_fast
    from mocapkit.markers.prioritized import DEFAULT_DAMPING, prioritized_torque

    kin = MarkerKinematics(human, names)
    fm = rigid_fast.flatten(human.model, kin.frame_ids)
    sw = np.sqrt(np.maximum(weights, 0.0))
    out = np.zeros((len(Q), human.nv))
    lock_rows = np.zeros((len(locked), human.nv))
    for i, name in enumerate(locked):
        lock_rows[i, human.dof_index(name)] = 1.0
    for f, q in enumerate(Q):
        R, t, S, _, _, A, h = rigid_fast.dynamics_terms(
            fm.parent, fm.R0, fm.p0, fm.axis, fm.mass, fm.com, fm.inertia, fm.gravity, q,
            np.zeros(human.nv),
        )  # fmt: skip
        P, J = rigid_fast.marker_kinematics(fm.parent, R, t, S, fm.marker_joint, fm.marker_offset)
        vis = np.isfinite(X[f, :, 0]) & (weights > 0)
        if not vis.any():
            continue
        Jm = (J[vis] * sw[vis, None, None]).reshape(-1, human.nv)
        Jr = np.ascontiguousarray(np.vstack([lock_rows, Jm]))
        dx = ((X[f, vis] - P[vis]) * sw[vis, None]).reshape(-1)
        LA = np.linalg.cholesky(A)
        zeros = np.zeros(len(Jr))
        rows_dx = np.concatenate([np.zeros(len(lock_rows)), dx])
        _, _, out[f] = prioritized_torque(
            A, LA, h, Jr, zeros, zeros, np.array([0, len(lock_rows), len(Jr)]),
            np.zeros(human.nv), rows_dx, True, DEFAULT_DAMPING,
        )  # fmt: skip
    return out


def determined_mask(
    human: HumanModel,
    tracked: Sequence[str],
    X: FloatArray,
    names: Sequence[str],
    locked: Mapping[str, Any],
) -> FloatArray:
    """(N, 6 + n_dof) bool: coordinate determined by some visible tracked marker."""
    index = {n: i for i, n in enumerate(names)}
    vis = np.isfinite(X[..., 0])
    seg_markers: dict[str, list[int]] = {}
    for n in tracked:
        seg_markers.setdefault(human.markers[n][0], []).append(index[n])
    n_frames = X.shape[0]
    out = np.zeros((n_frames, 6 + len(human.dof_names)), dtype=bool)
    all_tracked = [index[n] for n in tracked]
    out[:, :6] = (vis[:, all_tracked].sum(axis=1) >= 3)[:, None]
    dof_seg = human.dof_segment()
    for k, dof in enumerate(human.dof_names):
        if dof in locked:
            out[:, 6 + k] = True
            continue
        cols = [i for seg in human.descendants(dof_seg[dof]) for i in seg_markers.get(seg, [])]
        if cols:
            out[:, 6 + k] = vis[:, cols].any(axis=1)
    return out


@dataclass
class ReconstructionResult:
    """Joint angles and everything needed to judge them.

    Attributes:
        time: (N,) s.
        q: (N, nq) configurations.
        coordinate_names, coordinates: named coordinates (N, k) [m, rad]; NaN where not
            determined.
        marker_names: the M markers of the trial; tracked: those the method used.
        commanded, tracked_positions: (N, M, 3) captured and model markers [m].
        errors: (N, M) distance [m] for visible markers, NaN otherwise.
        dq: (N, nv) joint-error bound Δq = Jbar_⊗ Δx_⊗ (eq. 15) [rad; root translation m].
        levels: the marker subsets in priority order.
        elapsed_s: wall time of the reconstruction loop.
    """

    time: FloatArray
    q: FloatArray
    coordinate_names: tuple[str, ...]
    coordinates: FloatArray
    marker_names: tuple[str, ...]
    tracked: tuple[str, ...]
    commanded: FloatArray
    tracked_positions: FloatArray
    errors: FloatArray
    dq: FloatArray
    levels: list[list[str]]
    elapsed_s: float
    method: str
    mode: str
    angular: np.ndarray
    warnings: list[str] = field(default_factory=list)
    meta: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def build(
        cls,
        time: FloatArray,
        human: HumanModel,
        names: Sequence[str],
        tracked: Sequence[str],
        X: FloatArray,
        Q: FloatArray,
        dq: FloatArray,
        elapsed_s: float,
        method: str,
        mode: str,
        levels: list[list[str]],
        locked: Mapping[str, Any],
        warnings: list[str],
    ) -> ReconstructionResult:
        P = np.array([MarkerKinematics(human, names).positions(q) for q in Q]).reshape(X.shape)
        errors = np.linalg.norm(P - X, axis=2)
        coords = coordinates_from_q(human, Q)
        det = determined_mask(human, tracked, X, names, locked)
        coords = np.where(det, coords, np.nan)
        cnames = coordinate_names(human)
        never = [c for k, c in enumerate(cnames) if not det[:, k].any()]
        if never:
            warnings.append(
                f"{len(never)} coordinates are not determined by any tracked marker and are left "
                f"out of the outputs: {', '.join(never)}"
            )
            log.warning("%s", warnings[-1])
        partial = [c for k, c in enumerate(cnames) if det[:, k].any() and not det[:, k].all()]
        if partial:
            warnings.append(
                f"coordinates {', '.join(partial[:10])} are undetermined (NaN) in some frames "
                "where their markers are missing"
            )
            log.warning("%s", warnings[-1])
        return cls(
            time=np.asarray(time, dtype=float),
            q=Q,
            coordinate_names=cnames,
            coordinates=coords,
            marker_names=tuple(names),
            tracked=tuple(tracked),
            commanded=X,
            tracked_positions=P,
            errors=errors,
            dq=dq,
            levels=levels,
            elapsed_s=elapsed_s,
            method=method,
            mode=mode,
            angular=angular_columns(human),
            warnings=warnings,
        )

    # -- figures ---------------------------------------------------------------------------
    @property
    def n_frames(self) -> int:
        return int(self.time.shape[0])

    @property
    def fps(self) -> float:
        return self.n_frames / self.elapsed_s if self.elapsed_s > 0 else float("inf")

    def frame_rms(self, markers: Sequence[str] | None = None) -> FloatArray:
        """(N,) RMS over each frame's visible markers (default: the tracked ones) [m]."""
        names = self.tracked if markers is None else markers
        idx = [self.marker_names.index(n) for n in names]
        e = self.errors[:, idx]
        with np.errstate(invalid="ignore"):
            return np.sqrt(np.nanmean(e**2, axis=1))

    def dq_extremes(self) -> tuple[FloatArray, FloatArray]:
        """Per frame Δq_max and Δq_min over the rotational DOFs (eq. 17) [rad]."""
        rot = self.dq[:, 3:]
        return rot.max(axis=1), rot.min(axis=1)

    def metrics(self, markers: Sequence[str] | None = None) -> dict[str, Any]:
        """The figures of ``markers reconstruct --json``."""
        rms = self.frame_rms(markers)
        names = self.tracked if markers is None else markers
        idx = [self.marker_names.index(n) for n in names]
        return {
            "frames": self.n_frames,
            "fps": round(float(self.fps), 1),
            "marker_rms_mm": round(float(np.nanmean(rms)) * 1000, 2),
            "marker_max_mm": round(float(np.nanmax(self.errors[:, idx])) * 1000, 2),
            "joint_error_bound_deg_max": round(float(np.degrees(np.abs(self.dq[:, 3:]).max())), 3),
        }

    def column(self, name: str) -> FloatArray:
        return self.coordinates[:, self.coordinate_names.index(name)]

    # -- files -----------------------------------------------------------------------------
    def _output_columns(self) -> tuple[list[str], FloatArray]:
        keep = [
            k
            for k in range(len(self.coordinate_names))
            if np.isfinite(self.coordinates[:, k]).any()
        ]
        data = self.coordinates[:, keep].copy()
        ang = self.angular[keep]
        data[:, ang] = np.degrees(data[:, ang])
        return [self.coordinate_names[k] for k in keep], data

    def write_mot(self, path: str | Path) -> Path:
        """OpenSim ``.mot`` (degrees, pelvis in OpenSim's y-up ground; see coordinates)."""
        from mocapkit.io.opensim_table import write_table

        labels, data = self._output_columns()
        return write_table(path, self.time, labels, data, name="mocapkit_markers", in_degrees=True)

    def write_csv(self, path: str | Path) -> Path:
        """CSV with unit suffixes (``_m``, ``_deg``); NaN where undetermined."""
        labels, data = self._output_columns()
        ang = {c for c, a in zip(self.coordinate_names, self.angular, strict=True) if a}
        header = ["time_s"] + [f"{c}_deg" if c in ang else f"{c}_m" for c in labels]
        rows = np.column_stack([self.time, data])
        p = Path(path)
        np.savetxt(p, rows, delimiter=",", header=",".join(header), comments="", fmt="%.8g")
        return p

    def write_tracked_trc(self, path: str | Path) -> Path:
        """The model's markers over time as a TRC file (z-up world, mm)."""
        from mocapkit.io.trc import write_trc
        from mocapkit.markers.trajectories import MarkerTrajectories

        rate = 1.0 / float(np.median(np.diff(self.time))) if self.n_frames > 1 else 0.0
        traj = MarkerTrajectories(
            self.time, self.tracked_positions, self.marker_names, meta={"rate_hz": rate}
        )
        return write_trc(path, traj)
