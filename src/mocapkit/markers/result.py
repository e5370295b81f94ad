"""What a reconstruction returns: joint angles, tracked versus commanded markers, errors and
the paper's per-frame joint-error bounds (eq. 14-17), with writers for .mot, CSV and TRC.

Coordinates that no visible marker determines (structurally: no tracked marker visible on
the segment the DOF moves or below it, and no coordinate task holding it; see
:mod:`mocapkit.markers.determined`) are NaN in those frames; a column that is never
determined is dropped from the files, with a warning. Frames without any visible tracked
marker have no marker error and no bound: they are NaN in the per-frame series, left out
of the figures' means and maxima, and counted in a warning.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.human_model import HumanModel
from mocapkit.markers.bounds import POORLY_DETERMINED_DEG_PER_MM, BoundReport, bound_report
from mocapkit.markers.coordinates import (
    CoordinateMap,
    coordinate_map,
    coordinates_and_gimbal,
)
from mocapkit.markers.determined import column_determined, dof_determined
from mocapkit.markers.kinematics import MarkerKinematics

log = logging.getLogger(__name__)


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
        dq: (N, nv) joint-error bound Δq = Jbar_⊗ Δx_⊗ (eq. 15) of the model's DOFs [rad;
            root translation m]: NaN where the DOF is not determined, capped at the joint's
            range (:mod:`mocapkit.markers.bounds`); :attr:`coordinate_bound` is the same
            for the reported coordinates, which the figures use.
        levels: the marker subsets in priority order.
        elapsed_s: wall time of the reconstruction loop.
        rate_hz: the trial's declared frame rate (the time column may be rounded).
        held: (K,) coordinates held by a coordinate task (not fitted to markers).
        model_dof_names, model_dof_values: the model's DOFs that OpenSim's coordinates are
            computed from (the spine, neck and shoulders), (N, k) [rad]; NaN where the
            coordinates computed from them are.
        bound: the bound's report (capped entries, conditioning per frame and DOF).
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
    bound: BoundReport | None = None
    warnings: list[str] = field(default_factory=list)
    meta: dict[str, Any] = field(default_factory=dict)
    rate_hz: float | None = None
    held: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    model_dof_names: tuple[str, ...] = ()
    model_dof_values: FloatArray | None = None

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
        weights: FloatArray | None = None,
        with_total: bool = True,
        P: FloatArray | None = None,
        progress: Callable[[str, float, float], None] | None = None,
    ) -> ReconstructionResult:
        """Errors, named coordinates (NaN where undetermined) and the bound's report;
        ``weights`` (M,) of ``names`` (default 1) weigh the conditioning's fit;
        ``with_total``: also the bound that holds (``bound.total``); ``P`` (N, M, 3): the
        model's markers at Q when the method already has them."""
        if P is None:
            P = marker_positions(human, names, Q)
        P = np.asarray(P, dtype=float).reshape(X.shape)
        errors = np.linalg.norm(P - X, axis=2)
        cmap = coordinate_map(human)
        coords, gimbal = coordinates_and_gimbal(human, Q, cmap)
        coords = unwrap_in_time(coords, range(3, 6))  # a subject who turns: no +-180 jumps
        root, dofs = dof_determined(human, names, tracked, X, held=locked)
        det = column_determined(cmap, root, dofs)
        w = np.ones(len(names)) if weights is None else np.asarray(weights, dtype=float)
        in_fit = np.array([n in set(tracked) for n in names])
        report = bound_report(
            human, cmap, names, Q, X, np.where(in_fit, w, 0.0), dq, root, dofs,
            held=list(locked), columns=det, with_total=with_total, coords=coords,
            progress=progress,
        )  # fmt: skip
        structural = det
        det = det & ~report.unobserved
        coords = np.where(det, coords, np.nan)
        t = np.asarray(time, dtype=float)
        for msg in _coverage_warnings(
            cmap.names, structural, det, gimbal, report, t, _no_visible_frames(X, names, tracked)
        ):
            warnings.append(msg)
            log.warning("%s", msg)
        cnames = cmap.names
        behind, behind_values = _dofs_behind(human, cmap, Q, coords)
        return cls(
            time=t,
            q=Q,
            coordinate_names=cnames,
            coordinates=coords,
            marker_names=tuple(names),
            tracked=tuple(tracked),
            commanded=X,
            tracked_positions=P,
            errors=errors,
            dq=report.dq,
            levels=levels,
            elapsed_s=elapsed_s,
            method=method,
            mode=mode,
            angular=cmap.angular,
            bound=report,
            warnings=warnings,
            held=np.array(
                [kind == "dof" and human.dof_names[a] in locked for kind, a, _ in cmap.source]
            ),
            model_dof_names=tuple(human.dof_names[i] for i in behind),
            model_dof_values=behind_values,
        )

    # -- figures ---------------------------------------------------------------------------
    @property
    def n_frames(self) -> int:
        return int(self.time.shape[0])

    @property
    def fps(self) -> float:
        return self.n_frames / self.elapsed_s if self.elapsed_s > 0 else float("inf")

    def _errors_of(self, markers: Sequence[str] | None) -> FloatArray:
        names = self.tracked if markers is None else markers
        return self.errors[:, [self.marker_names.index(n) for n in names]]

    def visible_count(self, markers: Sequence[str] | None = None) -> np.ndarray:
        """(N,) number of visible markers per frame (default: the tracked ones)."""
        return np.isfinite(self._errors_of(markers)).sum(axis=1)

    def frame_rms(self, markers: Sequence[str] | None = None) -> FloatArray:
        """(N,) RMS over each frame's visible markers (default: the tracked ones) [m]; NaN in
        frames where none of them is visible (counted in :attr:`warnings`)."""
        e = self._errors_of(markers)
        n = np.isfinite(e).sum(axis=1)
        sq = np.where(np.isfinite(e), e**2, 0.0).sum(axis=1)
        out = np.full(e.shape[0], np.nan)
        out[n > 0] = np.sqrt(sq[n > 0] / n[n > 0])
        return out

    @property
    def coordinate_bound(self) -> FloatArray:
        """(N, K) the joint-error bound of the reported coordinates (eq. 15 through their
        Jacobian; NaN where undetermined, capped) [rad; translations m]."""
        if self.bound is None:
            return np.full(self.coordinates.shape, np.nan)
        return self.bound.dc

    @property
    def fitted_angles(self) -> np.ndarray:
        """(K,) bool: rotational coordinates a marker fit determines (not the translations,
        not those a coordinate task holds, whose bound is 0 by construction)."""
        held = self.held if self.held.shape == self.angular.shape else np.zeros_like(self.angular)
        return self.angular & ~held

    def dq_extremes(self) -> tuple[FloatArray, FloatArray]:
        """Per frame Δq_max and Δq_min over the determined rotational coordinates that
        markers fit (eq. 17) [rad]; NaN in frames where none is determined."""
        rot = self.coordinate_bound[:, self.fitted_angles]
        has = np.isfinite(rot).any(axis=1)
        hi = np.full(rot.shape[0], np.nan)
        lo = np.full(rot.shape[0], np.nan)
        hi[has] = np.max(np.where(np.isfinite(rot[has]), rot[has], -np.inf), axis=1)
        lo[has] = np.min(np.where(np.isfinite(rot[has]), rot[has], np.inf), axis=1)
        return hi, lo

    def metrics(self, markers: Sequence[str] | None = None) -> dict[str, Any]:
        """The figures of ``markers reconstruct --json`` (which adds the whole command's
        ``fps`` and ``seconds``): means and maxima over the frames where they exist (frames
        without a visible marker or a determined DOF are left out; None if there is none at
        all). ``solve_fps``: frames per second of the reconstruction loop alone."""
        rms = self.frame_rms(markers)
        e = self._errors_of(markers)
        seen = np.isfinite(rms)
        bound = np.abs(self.coordinate_bound[:, self.fitted_angles])
        has = np.isfinite(bound)

        def rounded(x: float | None, digits: int) -> float | None:
            return None if x is None else round(float(x), digits)

        out: dict[str, Any] = {
            "frames": self.n_frames,
            "solve_fps": round(float(self.fps), 1),
            "marker_rms_mm": rounded(rms[seen].mean() * 1000 if seen.any() else None, 2),
            "marker_max_mm": rounded(e[np.isfinite(e)].max() * 1000 if seen.any() else None, 2),
            "joint_error_bound_deg_max": rounded(
                np.degrees(bound[has].max()) if has.any() else None, 3
            ),
        }
        if self.bound is not None and self.bound.total is not None:
            tot = self.bound.total[:, self.fitted_angles]
            fin = np.isfinite(tot)
            out["joint_error_total_bound_deg_max"] = rounded(
                np.degrees(tot[fin].max()) if fin.any() else None, 3
            )
        return out

    def column(self, name: str) -> FloatArray:
        return self.coordinates[:, self.coordinate_names.index(name)]

    # -- files -----------------------------------------------------------------------------
    def _output_columns(self, with_model_dofs: bool = False) -> tuple[list[str], FloatArray]:
        keep = [
            k
            for k in range(len(self.coordinate_names))
            if np.isfinite(self.coordinates[:, k]).any()
        ]
        data = self.coordinates[:, keep].copy()
        ang = self.angular[keep]
        data[:, ang] = np.degrees(data[:, ang])
        labels = [self.coordinate_names[k] for k in keep]
        if with_model_dofs and self.model_dof_values is not None:
            extra = [
                i for i in range(len(self.model_dof_names))
                if np.isfinite(self.model_dof_values[:, i]).any()
            ]  # fmt: skip
            labels += [self.model_dof_names[i] for i in extra]
            data = np.column_stack([data, np.degrees(self.model_dof_values[:, extra])])
        return labels, data

    def write_mot(self, path: str | Path) -> Path:
        """OpenSim ``.mot`` (degrees, pelvis in OpenSim's y-up ground; see coordinates):
        OpenSim's coordinate names, then the model's own DOFs behind the computed ones
        (``abdomen_*``, ``thorax_*``, ``cervical_*``, ``head_extension``, ``shoulder_*``),
        so the same file poses mocapkit's exported model (:mod:`mocapkit.io.osim_model`)
        exactly; OpenSim ignores columns a model does not have."""
        from mocapkit.io.opensim_table import write_table

        labels, data = self._output_columns(with_model_dofs=True)
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

    def write_tracked_c3d(self, path: str | Path) -> Path:
        """The model's markers as a C3D file (mm) in the trial file's own axes, so it
        overlays the captured markers; a C3D trial's analogs, force platforms and events
        are written with them (:func:`mocapkit.io.c3d.write_c3d`)."""
        from mocapkit.io.c3d import C3DExtras, write_c3d
        from mocapkit.markers.trajectories import MarkerTrajectories

        rate = self.rate_hz or (1.0 / float(np.median(np.diff(self.time))))
        traj = MarkerTrajectories(
            _exact_times(self.time, rate), self.tracked_positions @ _file_axes(self).T,
            self.marker_names, meta={"rate_hz": rate},
        )  # fmt: skip
        extras = self.meta.get("c3d")
        return write_c3d(path, traj, extras if isinstance(extras, C3DExtras) else None)

    def write_tracked_trc(self, path: str | Path) -> Path:
        """The model's markers over time as a TRC file (mm) in OpenSim's y-up ground, the
        frame of the .mot's pelvis columns (``v_os = (x, z, -y)`` of our z-up world), at
        the trial's exact frame rate."""
        from mocapkit.io.trc import write_trc
        from mocapkit.markers.coordinates import Z_UP_TO_OPENSIM
        from mocapkit.markers.trajectories import MarkerTrajectories

        rate = self.rate_hz
        if rate is None:
            rate = 1.0 / float(np.median(np.diff(self.time))) if self.n_frames > 1 else 0.0
        traj = MarkerTrajectories(
            _exact_times(self.time, rate),
            self.tracked_positions @ Z_UP_TO_OPENSIM.T,
            self.marker_names,
            meta={"rate_hz": rate, "up_axis": "y"},
        )
        return write_trc(path, traj, rate_hz=rate)


def _dofs_behind(
    human: HumanModel, cmap: CoordinateMap, Q: FloatArray, coords: FloatArray
) -> tuple[list[int], FloatArray]:
    """The model DOFs (indices into ``q[7:]``) that reported coordinates are computed from
    and that are not reported under their own name, and their values (N, k) [rad], NaN in
    frames where any coordinate of their joint is NaN."""
    reported = {a for kind, a, _ in cmap.source if kind == "dof"}
    idx: list[int] = []
    cols: list[FloatArray] = []
    for c, ch in enumerate(cmap.chains):
        ks = [k for k, (kind, a, _) in enumerate(cmap.source) if kind == "derived" and a == c]
        undetermined = ~np.isfinite(coords[:, ks]).all(axis=1)
        for d in ch.dofs:
            if d in reported or d in idx:
                continue
            idx.append(d)
            cols.append(np.where(undetermined, np.nan, Q[:, 7 + d]))
    return idx, (np.column_stack(cols) if cols else np.zeros((len(Q), 0)))


def unwrap_in_time(values: FloatArray, columns: Iterable[int]) -> FloatArray:
    """A copy of ``values`` (N, K) [rad] whose ``columns`` are continuous in time: each
    step takes the 2 pi branch nearest the previous finite value (NaN gaps skipped)."""
    out = np.array(values, dtype=float, copy=True)
    for k in columns:
        fin = np.flatnonzero(np.isfinite(out[:, k]))
        if fin.size > 1:
            out[fin, k] = np.unwrap(out[fin, k])
    return out


def _exact_times(time: FloatArray, rate: float) -> FloatArray:
    """``time[0] + k / rate`` when ``time`` is that clock to a quarter frame (a time column
    rounded to a few decimals in the input file), else ``time``."""
    regular = time[0] + np.arange(len(time)) / rate
    return regular if np.abs(time - regular).max() <= 0.25 / rate else np.asarray(time)


def _file_axes(result: ReconstructionResult) -> FloatArray:
    """R with x_file = R x_zup for the trial's file axes (``meta["file_up_axis"]``)."""
    from mocapkit.markers.conventions import rotation_to_z_up

    return rotation_to_z_up(str(result.meta.get("file_up_axis") or "z")).T


def marker_positions(human: HumanModel, names: Sequence[str], Q: FloatArray) -> FloatArray:
    """(N, M, 3) the model's markers ``names`` at each configuration of Q (N, nq) [m]."""
    from mocapkit.markers import rigid_fast

    fm = rigid_fast.flatten(human.model, MarkerKinematics(human, names).frame_ids)
    Qc = np.ascontiguousarray(np.atleast_2d(Q), dtype=float)
    P = rigid_fast.marker_positions_trial(
        fm.parent, fm.R0, fm.p0, fm.axis, fm.marker_joint, fm.marker_offset, Qc
    )
    return np.asarray(P)


def _no_visible_frames(X: FloatArray, names: Sequence[str], tracked: Sequence[str]) -> np.ndarray:
    """(N,) frames where no tracked marker is visible."""
    keep = set(tracked)
    cols = [i for i, n in enumerate(names) if n in keep]
    return np.asarray(~np.isfinite(X[:, cols, 0]).any(axis=1))


def _coverage_warnings(
    cnames: Sequence[str],
    structural: np.ndarray,
    det: np.ndarray,
    gimbal: Mapping[str, np.ndarray],
    report: BoundReport,
    t: FloatArray,
    blind: np.ndarray,
) -> list[str]:
    """What the outputs leave out or cannot vouch for, in words (see ReconstructionResult)."""
    out = []
    never = [c for k, c in enumerate(cnames) if not det[:, k].any()]
    if never:
        out.append(
            f"{len(never)} coordinates are not determined by any tracked marker and are left "
            f"out of the outputs: {', '.join(never)}"
        )
    partial = [c for k, c in enumerate(cnames) if det[:, k].any() and not det[:, k].all()]
    if partial:
        out.append(
            f"coordinates {', '.join(partial[:10])}{' ...' if len(partial) > 10 else ''} are "
            "undetermined (NaN) in some frames where their markers are missing"
        )
    unobserved = structural & report.unobserved
    if unobserved.any():
        counts = [(c, int(unobserved[:, k].sum())) for k, c in enumerate(cnames)]
        worst = sorted((kv for kv in counts if kv[1]), key=lambda kv: -kv[1])[:8]
        out.append(
            "numerically undetermined, so NaN there (the visible markers leave a direction "
            "of them unobserved, e.g. one marker for several DOFs): "
            + ", ".join(f"{c} in {n} frames" for c, n in worst)
        )
    if blind.any():
        idx = np.flatnonzero(blind)
        out.append(
            f"{idx.size} of {len(t)} frames have no visible tracked marker (first at "
            f"t = {t[idx[0]]:.3f} s, last at t = {t[idx[-1]]:.3f} s): the pose is held there "
            "and they have no marker error and no error bound (NaN in the per-frame series, "
            "left out of marker_rms_mm and the other figures)"
        )
    for joint, close in gimbal.items():
        n_close = int((close & det[:, list(cnames).index(joint)]).sum())
        if n_close:
            out.append(
                f"{joint} within 10 deg of +-90 deg in {n_close} frames (gimbal lock of "
                "OpenSim's rotation order): the other two angles of that joint are "
                "ill-defined there (the model's own DOFs in q are not)"
            )
    n_capped = int(report.capped.any(axis=1).sum())
    if n_capped:
        out.append(
            f"the joint-error bound (eq. 15) exceeded a joint's range in {n_capped} frames "
            "and is capped at the range there (the linearisation is meaningless that far)"
        )
    if report.poorly_determined:
        worst = sorted(report.poorly_determined.items(), key=lambda kv: -kv[1])[:6]
        out.append(
            "poorly determined by the visible markers (more than "
            f"{POORLY_DETERMINED_DEG_PER_MM:g} deg per mm of marker error): "
            + ", ".join(f"{d} in {n} frames" for d, n in worst)
            + "; their joint-error bounds rest on an ill-conditioned fit"
        )
    return out
