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
from mocapkit.markers.bounds import BoundReport, bound_report
from mocapkit.markers.coordinates import (
    CoordinateMap,
    coordinate_map,
    coordinates_and_gimbal,
)
from mocapkit.markers.coverage import Coverage, MetricsTally
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
    coverage: Coverage | None = None
    root_angles_tail: FloatArray | None = None

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
        root_angles_before: FloatArray | None = None,
        quiet: bool = False,
    ) -> ReconstructionResult:
        """Errors, named coordinates (NaN where undetermined) and the bound's report;
        ``weights`` (M,) of ``names`` (default 1) weigh the conditioning's fit;
        ``with_total``: also the bound that holds (``bound.total``); ``P`` (N, M, 3): the
        model's markers at Q when the method already has them.

        A piece of a longer trial: ``root_angles_before`` (3,) the pelvis rotations of the
        frame before it (its ``root_angles_tail``), so they continue without a 2 pi jump;
        ``quiet``: its :attr:`coverage` is not turned into warnings (the whole trial's
        is, once)."""
        if P is None:
            P = marker_positions(human, names, Q)
        P = np.asarray(P, dtype=float).reshape(X.shape)
        errors = np.linalg.norm(P - X, axis=2)
        cmap = coordinate_map(human)
        coords, gimbal = coordinates_and_gimbal(human, Q, cmap)
        # a subject who turns: no +-180 jumps
        if root_angles_before is None:
            coords = unwrap_in_time(coords, range(3, 6))
        else:
            coords = unwrap_in_time(np.vstack([root_angles_before_row(root_angles_before,
                                    coords.shape[1]), coords]), range(3, 6))[1:]  # fmt: skip
        tail = _last_finite(coords[:, 3:6])
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
        coverage = Coverage.of(
            cmap.names, structural, det, gimbal, report, t, _no_visible_frames(X, names, tracked)
        )
        if not quiet:
            for msg in coverage.warnings():
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
            coverage=coverage,
            root_angles_tail=tail if root_angles_before is None
            else np.where(np.isfinite(tail), tail, root_angles_before),
        )  # fmt: skip

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
        tally = MetricsTally()
        tally.add(self, markers)
        return tally.metrics()

    def column(self, name: str) -> FloatArray:
        return self.coordinates[:, self.coordinate_names.index(name)]

    # -- files -----------------------------------------------------------------------------
    def _output_columns(self, with_model_dofs: bool = False) -> tuple[list[str], FloatArray]:
        dofs = self.model_dof_values if with_model_dofs else None
        keep = np.asarray(np.isfinite(self.coordinates).any(axis=0))
        keep_dofs = None if dofs is None else np.asarray(np.isfinite(dofs).any(axis=0))
        return output_columns(
            self.coordinate_names, self.angular, self.coordinates, keep,
            self.model_dof_names, dofs, keep_dofs,
        )  # fmt: skip

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
        p = Path(path)
        with open(p, "w") as f:
            f.write(csv_header(labels, self.coordinate_names, self.angular) + "\n")
            write_csv_rows(f, self.time, data)
        return p

    def write_tracked_c3d(self, path: str | Path) -> Path:
        """The model's markers as a C3D file (mm) in the trial file's own axes, so it
        overlays the captured markers; a C3D trial's analogs, force platforms and events
        are written with them (:func:`mocapkit.io.c3d.write_c3d`)."""
        rate = self.rate_hz or (1.0 / float(np.median(np.diff(self.time))))
        return write_tracked_c3d(
            path, self.time, rate, self.tracked_positions, self.marker_names,
            str(self.meta.get("file_up_axis") or "z"), self.meta.get("c3d"),
        )  # fmt: skip

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


def output_columns(
    names: Sequence[str],
    angular: np.ndarray,
    coords: FloatArray,
    keep: np.ndarray,
    dof_names: Sequence[str] = (),
    dofs: FloatArray | None = None,
    keep_dofs: np.ndarray | None = None,
) -> tuple[list[str], FloatArray]:
    """The files' labels and rows (angles in degrees): the coordinates ``keep`` (K,) bool,
    then the model DOFs ``keep_dofs`` of ``dofs`` (N, k) when given."""
    idx = np.flatnonzero(keep)
    data = coords[:, idx].copy()
    ang = angular[idx]
    data[:, ang] = np.degrees(data[:, ang])
    labels = [names[int(k)] for k in idx]
    if dofs is not None and keep_dofs is not None:
        extra = np.flatnonzero(keep_dofs)
        labels += [dof_names[int(i)] for i in extra]
        data = np.column_stack([data, np.degrees(dofs[:, extra])])
    return labels, data


def csv_header(labels: Sequence[str], names: Sequence[str], angular: np.ndarray) -> str:
    """The CSV's header line: unit suffixes ``_deg`` and ``_m``."""
    ang = {c for c, a in zip(names, angular, strict=True) if a}
    return ",".join(["time_s"] + [f"{c}_deg" if c in ang else f"{c}_m" for c in labels])


def write_csv_rows(f: Any, time: FloatArray, data: FloatArray) -> None:
    """CSV rows ``time, data...`` to an open text file."""
    np.savetxt(f, np.column_stack([time, data]), delimiter=",", fmt="%.8g")


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


def write_tracked_c3d(
    path: str | Path,
    time: FloatArray,
    rate: float,
    P: FloatArray,
    names: Sequence[str],
    file_up_axis: str,
    extras: Any,
) -> Path:
    """The model's markers P (N, M, 3) [m, z-up] as a C3D in the trial file's axes, with a
    C3D trial's analogs, force platforms and events (``extras``)."""
    from mocapkit.io.c3d import C3DExtras, write_c3d
    from mocapkit.markers.conventions import rotation_to_z_up
    from mocapkit.markers.trajectories import MarkerTrajectories

    R = rotation_to_z_up(file_up_axis).T  # x_file = R x_zup
    traj = MarkerTrajectories(
        _exact_times(time, rate), P @ R.T, tuple(names), meta={"rate_hz": rate}
    )
    return write_c3d(path, traj, extras if isinstance(extras, C3DExtras) else None)


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


def root_angles_before_row(values: FloatArray, k: int) -> FloatArray:
    """(1, k) a row holding the pelvis rotations ``values`` (3,) in columns 3-5."""
    row = np.full((1, k), np.nan)
    row[0, 3:6] = values
    return row


def _last_finite(values: FloatArray) -> FloatArray:
    """(k,) each column's last finite value of ``values`` (N, k) (NaN when none)."""
    out = np.full(values.shape[1], np.nan)
    for j in range(values.shape[1]):
        fin = np.flatnonzero(np.isfinite(values[:, j]))
        if fin.size:
            out[j] = values[fin[-1], j]
    return out
