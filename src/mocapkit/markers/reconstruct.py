"""The marker pipeline: files in, checked and cleaned trajectories, a scaled subject, then
joint angles by direct marker control (``method="osc"``) or IK (``method="ik"``).

Every check that changes or drops something says so (``log.warning`` and
``ReconstructionResult.warnings``); anything that would give a wrong skeleton is an error.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.anthropometry import Sex
from mocapkit.body.markersets import MarkerSet, guess_markerset, load_markerset
from mocapkit.body.scaling import Subject
from mocapkit.errors import ConfigError, DataError
from mocapkit.markers import conventions
from mocapkit.markers.bounds import joint_error_bounds
from mocapkit.markers.cleaning import CleaningReport, fill_gaps, lowpass
from mocapkit.markers.coordinates import resolve_coordinate_tasks
from mocapkit.markers.determined import dof_determined
from mocapkit.markers.grouping import make_levels
from mocapkit.markers.ik import IKParams, initial_root_pose, solve_ik
from mocapkit.markers.osc import DirectMarkerController, OSCParams, reconstruct_offline
from mocapkit.markers.result import ReconstructionResult
from mocapkit.markers.subject import Warnings as _Warnings
from mocapkit.markers.subject import check_static_is_not_trial, scaled_subject
from mocapkit.markers.trajectories import MarkerTrajectories

log = logging.getLogger(__name__)

Method = Literal["osc", "ik"]
Mode = Literal["offline", "online"]


@dataclass(frozen=True)
class ReconstructionOptions:
    """How to reconstruct (defaults are what ``mocapkit markers reconstruct`` uses).

    ``total_bound``: also compute the joint-error bound that holds
    (:mod:`mocapkit.markers.bound_fit`, a least-squares fit per frame); eq. 15's bound and
    the conditioning are always computed."""

    method: Method = "osc"
    mode: Mode = "offline"
    grouping: str = "single"
    units: str = "auto"
    up_axis: str = "auto"
    fill_gaps: str = "none"
    max_gap_s: float = 0.25
    lowpass_hz: float | None = None
    start_s: float | None = None
    end_s: float | None = None
    total_bound: bool = False
    osc: OSCParams = field(default_factory=OSCParams)
    ik: IKParams = field(default_factory=IKParams)

    def __post_init__(self) -> None:
        if self.method not in ("osc", "ik"):
            raise ConfigError(f"method: expected 'osc' or 'ik', got {self.method!r}")
        if self.mode not in ("offline", "online"):
            raise ConfigError(f"mode: expected 'offline' or 'online', got {self.mode!r}")


def load_markers(path: str | Path, units: str | None = None) -> MarkerTrajectories:
    """Read a ``.c3d`` or ``.trc`` file (units override as given, else declared)."""
    from mocapkit.io.c3d import read_c3d
    from mocapkit.io.trc import read_trc

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such marker file")
    u = None if units in (None, "auto") else units
    if p.suffix.lower() == ".c3d":
        return read_c3d(p, units=u)
    if p.suffix.lower() == ".trc":
        return read_trc(p, units=u)
    raise ConfigError(f"{p}: unknown marker file type {p.suffix!r}; expected .c3d or .trc")


def _set_columns(
    traj: MarkerTrajectories,
    ms: MarkerSet,
    warnings: _Warnings,
    role: str,
    ever: np.ndarray | None = None,
) -> tuple[tuple[str, ...], list[int]]:
    """The markers of the set in the trial (the set's spelling) and their columns; warns
    about the rest. ``ever`` (M,): which of the trial's markers appear at all, when
    ``traj`` is only the start of a longer trial."""
    match = ms.match(traj.names)
    src = traj.meta.get("source", role)
    if not match.index:
        raise DataError(
            f"{src}: none of its markers ({', '.join(traj.names[:8])}...) is in marker set "
            f"{ms.name!r}; pass the right --markerset (or a YAML file for your set)"
        )
    if match.extra:
        warnings.add(
            f"{src}: {len(match.extra)} markers are not in marker set {ms.name!r} and are ignored "
            f"({', '.join(match.extra[:10])}{' ...' if len(match.extra) > 10 else ''}); add them "
            "to a YAML marker set to use them"
        )
    names = [n for n in ms.names if n in match.index]
    cols = [match.index[n] for n in names]
    seen = np.asarray(np.isfinite(traj.positions[:, :, 0]).any(axis=0) if ever is None else ever)
    never = [n for n, c in zip(names, cols, strict=True) if not seen[c]]
    if never:
        warnings.add(
            f"{src}: markers {', '.join(never)} never appear (all frames missing); they are "
            "dropped. Check their labels in the capture software"
        )
        keep = [i for i, n in enumerate(names) if n not in never]
        names = [names[i] for i in keep]
        cols = [cols[i] for i in keep]
    return tuple(names), cols


def _to_set_names(
    traj: MarkerTrajectories, ms: MarkerSet, warnings: _Warnings, role: str
) -> MarkerTrajectories:
    """Keep the markers of the set (renamed to the set's spelling), warn about the rest."""
    names, cols = _set_columns(traj, ms, warnings, role)
    return MarkerTrajectories(traj.time, traj.positions[:, cols], names, meta=dict(traj.meta))


@dataclass(frozen=True)
class Preparation:
    """How a trial's frames, as read, become the reconstruction's: units corrected, the
    marker set's columns under its names, z up (:func:`plan_preparation`)."""

    units: conventions.UnitCheck
    columns: tuple[int, ...]
    names: tuple[str, ...]
    up: str

    def apply(self, traj: MarkerTrajectories) -> MarkerTrajectories:
        t = conventions.apply_units(traj, self.units)
        t = MarkerTrajectories(
            t.time, t.positions[:, list(self.columns)], self.names, meta=dict(t.meta)
        )
        return conventions.to_z_up(t, self.up)


def plan_preparation(
    trial: MarkerTrajectories,
    static: MarkerTrajectories | None,
    ms: MarkerSet,
    options: ReconstructionOptions,
    warnings: _Warnings,
    ever: np.ndarray | None = None,
) -> tuple[Preparation, MarkerTrajectories, MarkerTrajectories | None]:
    """Units, names and axes decided from the trial (or, with ``ever``, its start) and the
    static trial; returns them, the trial prepared, and the static trial in metres, z-up,
    named as in the set."""
    explicit = options.units != "auto"
    if static is not None:
        s_check = conventions.check_units(static, explicit=explicit)
        if s_check.message:
            warnings.append(s_check.message)
        static = conventions.apply_units(static, s_check)
    check = conventions.check_units(trial, explicit=explicit)
    if check.message:
        warnings.append(check.message)
    names, cols = _set_columns(conventions.apply_units(trial, check), ms, warnings, "trial", ever)
    segments = {m.name: m.segment for m in ms.markers}
    if static is not None:
        static = _to_set_names(static, ms, warnings, "static trial")
        reference = static
    else:
        reference = MarkerTrajectories(
            trial.time, trial.positions[:, cols] * check.factor, names, meta=dict(trial.meta)
        )
    up = conventions.resolve_up_axis(reference, segments, options.up_axis)
    if up != "z":
        log.info("converting %s-up files to z-up", up)
    prep = Preparation(check, tuple(cols), names, up)
    prepared = prep.apply(trial)
    if static is not None:
        static = conventions.to_z_up(static, up)
        # the trial must be z-up too: its own up direction must agree
        found = conventions.detect_up_axis(prepared, segments)
        if found is not None and found.axis != "z" and found.angle_deg < 45:
            raise DataError(
                f"{prepared.meta.get('source', 'trial')}: after the static trial's axis "
                f"conversion ({up}-up) the trial's body points {found.axis}; the two files "
                "use different axes. Fix: export both with the same axes (or pass --up-axis)"
            )
    return prep, prepared, static


def prepare(
    trial: MarkerTrajectories,
    static: MarkerTrajectories | None,
    ms: MarkerSet,
    options: ReconstructionOptions,
    warnings: _Warnings,
) -> tuple[MarkerTrajectories, MarkerTrajectories | None, CleaningReport]:
    """Units, axes, names, cleaning: both trials in metres, z-up, named as in the set."""
    _, trial, static = plan_preparation(trial, static, ms, options, warnings)
    if options.start_s is not None or options.end_s is not None:
        trial = trial.between(options.start_s, options.end_s)
    trial, report = fill_gaps(trial, options.fill_gaps, options.max_gap_s, marker_clusters(ms))
    if options.lowpass_hz:
        trial, report = lowpass(trial, options.lowpass_hz, report=report)
    warn_open_gaps(report, trial.n_frames, trial.rate_hz, warnings)
    return trial, static, report


def marker_clusters(ms: MarkerSet) -> dict[str, list[str]]:
    """Marker -> the other markers of its segment (the rigid-cluster gap fill's donors)."""
    return {
        m.name: [o.name for o in ms.markers if o.segment == m.segment and o.name != m.name]
        for m in ms.markers
    }


def warn_open_gaps(report: CleaningReport, n: int, rate: float, warnings: _Warnings) -> None:
    """The interior gaps cleaning left open, with the longest, as one warning."""
    long_gaps = [g for g in report.left_open if g.start > 0 and g.stop < n]
    if long_gaps:
        worst = max(long_gaps, key=lambda g: g.length)
        warnings.add(
            f"{len(long_gaps)} gaps are not filled (longest: {worst.marker}, frames "
            f"{worst.start}-{worst.stop - 1}, {worst.length / rate:.2f} s); those markers "
            "are left out of those frames (--fill-gaps and --max-gap-s fill short gaps)"
        )


def _initial_pose(
    subject: Subject, names: Sequence[str], X0: FloatArray, weights: FloatArray
) -> FloatArray:
    """Best IK solution of the first frame from the neutral and the static pose."""
    human = subject.human
    best: tuple[float, FloatArray] | None = None
    for start in (human.neutral(), subject.static_q):
        q0 = initial_root_pose(human, names, X0, start)
        sol = solve_ik(
            human, names, X0[None], weights, q0, subject.markerset.coordinate_tasks,
            q_posture=human.neutral(), params=IKParams(max_iter_first=300),
        )  # fmt: skip
        if best is None or sol.cost[0] < best[0]:
            best = (float(sol.cost[0]), sol.q[0])
    assert best is not None
    return best[1]


def _warm_up(
    subject: Subject,
    names: Sequence[str],
    X: FloatArray,
    weights: FloatArray,
    levels: Sequence[Sequence[str]],
    q_init: FloatArray,
    rate: float,
    options: ReconstructionOptions,
) -> None:
    """Run the kernels on two frames so that compiling (or loading numba's cache) is not
    counted in the frame rate."""
    human, ms = subject.human, subject.markerset
    if options.method == "ik":
        solve_ik(human, names, X[:2], weights, q_init, ms.coordinate_tasks, params=options.ik)
    elif options.osc.backend == "fast":
        wmap = dict(zip(names, weights, strict=True))
        reconstruct_offline(
            human, names, X[:2], rate, levels, ms.coordinate_tasks, q_init, None, options.osc,
            wmap,
        )  # fmt: skip


Progress = Callable[[str, float, float], None]  # (step, done, total): a progress bar


def reconstruct(
    trial: MarkerTrajectories,
    subject: Subject,
    options: ReconstructionOptions,
    warnings: list[str] | None = None,
    progress: Progress | None = None,
) -> ReconstructionResult:
    """Joint angles for a prepared trial (metres, z-up, set names); ``progress(step, done,
    total)`` is told how the long steps advance."""

    def solve_progress(done: int, total: int) -> None:
        if progress is not None:
            progress("reconstruction", done, total)

    warn = _Warnings(warnings or [])
    human = subject.human
    plan = plan_tracking(trial.names, subject, options)
    names, weights, levels, tracked, tasks = (
        plan.names,
        plan.weights,
        plan.levels,
        plan.tracked,
        plan.tasks,
    )
    X = np.ascontiguousarray(trial.select(names).positions)
    first = int(np.argmax(np.isfinite(X[..., 0]).sum(axis=1) >= 3))
    if np.isfinite(X[first, :, 0]).sum() < 3:
        raise DataError("no frame has 3 visible markers; nothing can be reconstructed")
    q_init = _initial_pose(subject, names, X[first], weights)
    rate = trial.rate_hz
    _warm_up(subject, names, X, weights, levels, q_init, rate, options)
    t0 = time.perf_counter()
    P = None
    if options.method == "ik":
        sol = solve_ik(
            human, names, X, weights, q_init, tasks, q_posture=human.neutral(),
            params=options.ik, progress=solve_progress,
        )  # fmt: skip
        elapsed = time.perf_counter() - t0
        Q = sol.q
        tracked_w = np.where([n in set(tracked) for n in names], weights, 0.0)
        _, det = dof_determined(human, names, tracked, X, held=tasks)
        dq = joint_error_bounds(human, names, Q, X, tracked_w, ~det, list(tasks))
    else:
        wmap = dict(zip(names, weights, strict=True))
        if options.mode == "online":
            ctrl = DirectMarkerController(
                human, names, levels, tasks, q_init, rate, human.neutral(),
                options.osc, wmap,
            )  # fmt: skip
            frames = [ctrl.step(x) for x in X]
            elapsed = time.perf_counter() - t0
            Q = np.array([f.q for f in frames])
            dq = np.array([f.dq for f in frames])
        else:
            Q, P, dq, _ = reconstruct_offline(
                human, names, X, rate, levels, tasks, q_init, human.neutral(),
                options.osc, wmap, progress=solve_progress,
            )  # fmt: skip
            elapsed = time.perf_counter() - t0
    result = ReconstructionResult.build(
        trial.time, human, names, tracked, X, Q, dq, elapsed, options.method, options.mode,
        [list(level) for level in levels], tasks, warn, weights,
        with_total=options.total_bound, P=P, progress=progress,
    )  # fmt: skip
    result.rate_hz = rate
    result.meta["file_up_axis"] = trial.meta.get("converted_from_up_axis", "z")
    if trial.meta.get("c3d") is not None:
        result.meta["c3d"] = trial.meta["c3d"]
    check_tracking(bool(np.isfinite(result.coordinates[:, result.fitted_angles]).any()), plan, warn)
    result.warnings[:] = list(warn)
    return result


@dataclass(frozen=True)
class TrackingPlan:
    """Which markers a reconstruction uses and how (:func:`plan_tracking`)."""

    names: list[str]  # the trial's markers the model has
    weights: FloatArray  # (M,) their weights
    levels: tuple[tuple[str, ...], ...]  # priority levels (one for IK)
    tracked: list[str]  # the markers in the levels
    tasks: dict[str, Any]  # coordinate tasks, resolved on the model
    unregistered: frozenset[str]  # markers the static trial did not place


def plan_tracking(
    trial_names: Sequence[str], subject: Subject, options: ReconstructionOptions
) -> TrackingPlan:
    """The markers, weights, priority levels and coordinate tasks of a reconstruction."""
    human, ms = subject.human, subject.markerset
    tasks, notes = resolve_coordinate_tasks(human, ms.coordinate_tasks)
    for note in notes:
        log.info("%s", note)
    names = [n for n in trial_names if n in human.markers]
    weights = np.array([ms.spec(n).weight for n in names])
    levels: tuple[tuple[str, ...], ...]
    if options.method == "osc":
        segment_of = {n: human.markers[n][0] for n in names}
        levels = tuple(tuple(level) for level in make_levels(
            options.grouping, names, ms, segment_of, dict(zip(names, weights, strict=True)),
            human.segment_depth(),
        ))  # fmt: skip
        tracked = [n for level in levels for n in level]
    else:
        levels = (tuple(n for n, w in zip(names, weights, strict=True) if w > 0),)
        tracked = list(levels[0])
    if not tracked:
        raise DataError("no marker left to track; check the marker set and the trial's labels")
    unregistered = frozenset(subject.report.get("unregistered_markers", ()))
    return TrackingPlan(names, weights, levels, tracked, dict(tasks), unregistered)


def check_tracking(any_fitted: bool, plan: TrackingPlan, warn: _Warnings) -> None:
    """Refuse a reconstruction whose markers determine no joint angle (``any_fitted``: a
    fitted angle is finite in some frame); warn about tracked markers the static trial
    did not place."""
    tracked = plan.tracked
    if not any_fitted:
        raise DataError(
            f"the {len(tracked)} tracked markers ({', '.join(tracked[:8])}"
            f"{' ...' if len(tracked) > 8 else ''}) determine no joint angle of the model: "
            "its pelvis and trunk stay free. Track more markers (--grouping paper puts the "
            "paper's levels above all the others; the default is single)"
        )
    if plan.unregistered & set(tracked):
        warn.add(
            f"markers {', '.join(sorted(plan.unregistered & set(tracked)))} were not in the "
            "static trial: their offsets are the marker set's generic guesses"
        )


def apply_ik_setup(
    ms: MarkerSet, options: ReconstructionOptions, setup_path: str | Path, warnings: _Warnings
) -> tuple[MarkerSet, ReconstructionOptions]:
    """An OpenSim IK setup's marker weights and coordinate tasks on the marker set, its time
    range on the options (unless they set one). Markers the setup does not name keep the
    set's weights (said in a warning); markers it names that the set lacks are a warning."""
    import dataclasses

    from mocapkit.io.opensim_ik_setup import read_ik_setup

    setup = read_ik_setup(setup_path)
    names = set(ms.names)
    unknown = [n for n in setup.marker_weights if n not in names]
    if unknown:
        warnings.add(
            f"{setup_path}: markers {', '.join(unknown[:10])} are not in marker set "
            f"{ms.name!r}; their IK weights are ignored (add them to a YAML marker set)"
        )
    unnamed = [n for n in ms.names if n not in setup.marker_weights]
    if unnamed:
        warnings.add(
            f"{setup_path}: names no IK task for markers {', '.join(unnamed[:10])}"
            f"{' ...' if len(unnamed) > 10 else ''}; they keep marker set {ms.name!r}'s weights"
        )
    markers = tuple(
        dataclasses.replace(m, weight=setup.marker_weights.get(m.name, m.weight))
        for m in ms.markers
    )
    ms = dataclasses.replace(ms, markers=markers, coordinate_tasks=dict(setup.coordinate_tasks))
    if setup.time_range is not None and options.start_s is None and options.end_s is None:
        options = dataclasses.replace(
            options, start_s=setup.time_range[0], end_s=setup.time_range[1]
        )
    if setup.ignored:
        log.info("%s: settings without effect here: %s", setup_path, ", ".join(setup.ignored))
    return ms, options


KNOWN_SET_FRACTION = 0.6  # a preset must name this share of the trial's labels


def choose_markerset(trial: MarkerTrajectories, warnings: _Warnings) -> MarkerSet:
    """The preset that names most of the trial's labels when it names most of them and
    covers the lower limbs; else a set assigned from the labels and the motion
    (:mod:`mocapkit.body.markerset_auto`), reported in a warning; else an error with the
    markers and a YAML to write."""
    from mocapkit.body.markerset_auto import auto_markerset, require_lower_limbs

    src = trial.meta.get("source", "trial")
    ever = np.asarray(trial.visible.any(axis=0))
    seen = [n for n, v in zip(trial.names, ever.tolist(), strict=True) if v]
    try:
        ms, match = guess_markerset(trial.names)
    except ConfigError:
        ms, match = None, None
    if ms is not None and match is not None:
        share = len(match.index) / max(1, len(seen))
        present = [n for n in ms.names if n in match.index]
        covered = {ms.spec(n).segment for n in present}
        from mocapkit.body.markerset_auto import LOWER_LIMB

        if share >= KNOWN_SET_FRACTION and all(s in covered for s in LOWER_LIMB):
            log.info("marker set %s matches %d of the trial's labels", ms.name, len(match.index))
            return ms
    auto, report = auto_markerset(seen, trial.select(seen).positions)
    require_lower_limbs(auto, seen, str(src))
    warnings.add(
        f"{src}: no preset knows these labels ({', '.join(seen[:6])}...); markers assigned to "
        "segments from their labels and the motion (*: by moving rigidly with that "
        "segment): " + "; ".join(report.lines()) + ". Check it; to change it, save it "
        "(markers reconstruct --save-markerset FILE), edit and pass --markerset FILE"
    )
    return auto


def run(
    trial_path: str | Path,
    static_path: str | Path | None,
    markerset: str | Path | None,
    height_m: float | None,
    mass_kg: float | None,
    options: ReconstructionOptions | None = None,
    sex: Sex = "male",
    ik_setup: str | Path | None = None,
    progress: Progress | None = None,
) -> tuple[ReconstructionResult, Subject, CleaningReport]:
    """Files to joint angles: load, check, clean, calibrate, reconstruct.

    ``height_m`` None: estimated from the static trial (vertical extent of its markers);
    ``mass_kg`` None: 75 kg (only the simulated dynamics depend on it, not the angles of IK).
    ``ik_setup``: an OpenSim IK setup XML (:func:`apply_ik_setup`).
    """
    opts = options or ReconstructionOptions()
    warn = _Warnings()
    trial = load_markers(trial_path, opts.units)
    static = load_markers(static_path, opts.units) if static_path is not None else None
    check_static_is_not_trial(trial_path, static_path)
    if markerset is None:
        ms = choose_markerset(trial, warn)
    else:
        ms = load_markerset(markerset)
    if ik_setup is not None:
        ms, opts = apply_ik_setup(ms, opts, ik_setup, warn)
    trial, static, cleaning = prepare(trial, static, ms, opts, warn)
    subject = scaled_subject(trial, static, ms, height_m, mass_kg, sex, warn)
    result = reconstruct(trial, subject, opts, list(warn), progress)
    result.meta.update(
        {
            "marker_set": ms.name,
            "cleaning": cleaning.summary(),
            "scaling": subject.report.get("segment_scales", {}),
            "source": str(trial_path),
            "static": None if static_path is None else str(static_path),
            "ik_setup": None if ik_setup is None else str(ik_setup),
        }
    )
    return result, subject, cleaning


def describe(result: ReconstructionResult) -> dict[str, Any]:
    """The CLI's JSON figures (exact key set of issue 5)."""
    return result.metrics()
