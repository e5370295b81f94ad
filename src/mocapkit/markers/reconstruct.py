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
from mocapkit.body.scaling import Subject, scale_from_static
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
from mocapkit.markers.trajectories import MarkerTrajectories

log = logging.getLogger(__name__)

Method = Literal["osc", "ik"]
Mode = Literal["offline", "online"]
RIGID_PAIR_TOLERANCE_M = 0.015  # above: a warning (skin motion, a marker moved)
RIGID_PAIR_REFUSE_M = 0.04  # above: another subject, or swapped labels
STATIC_SPEED_REFUSE_M_S = 0.1  # a "static" trial whose stillest 0.5 s moves this fast
DEFAULT_MASS_KG = 75.0


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


class _Warnings(list[str]):
    def add(self, msg: str) -> None:
        log.warning("%s", msg)
        self.append(msg)


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


def _to_set_names(
    traj: MarkerTrajectories, ms: MarkerSet, warnings: _Warnings, role: str
) -> MarkerTrajectories:
    """Keep the markers of the set (renamed to the set's spelling), warn about the rest."""
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
    pos = traj.positions[:, [match.index[n] for n in names]]
    never = [n for i, n in enumerate(names) if not np.isfinite(pos[:, i, 0]).any()]
    if never:
        warnings.add(
            f"{src}: markers {', '.join(never)} never appear (all frames missing); they are "
            "dropped. Check their labels in the capture software"
        )
        keep = [i for i, n in enumerate(names) if n not in never]
        names = [names[i] for i in keep]
        pos = pos[:, keep]
    return MarkerTrajectories(traj.time, pos, tuple(names), meta=dict(traj.meta))


def prepare(
    trial: MarkerTrajectories,
    static: MarkerTrajectories | None,
    ms: MarkerSet,
    options: ReconstructionOptions,
    warnings: _Warnings,
) -> tuple[MarkerTrajectories, MarkerTrajectories | None, CleaningReport]:
    """Units, axes, names, cleaning: both trials in metres, z-up, named as in the set."""
    explicit = options.units != "auto"
    for label, t in (("static", static), ("trial", trial)):
        if t is None:
            continue
        check = conventions.check_units(t, explicit=explicit)
        if check.message:
            warnings.append(check.message)
        if label == "static":
            static = conventions.apply_units(t, check)
        else:
            trial = conventions.apply_units(t, check)
    trial = _to_set_names(trial, ms, warnings, "trial")
    segments = {m.name: m.segment for m in ms.markers}
    reference = static if static is not None else trial
    if static is not None:
        static = _to_set_names(static, ms, warnings, "static trial")
    up = conventions.resolve_up_axis(
        static if static is not None else reference, segments, options.up_axis
    )
    if up != "z":
        log.info("converting %s-up files to z-up", up)
    trial = conventions.to_z_up(trial, up)
    if static is not None:
        static = conventions.to_z_up(static, up)
        # the trial must be z-up too: its own up direction must agree
        found = conventions.detect_up_axis(trial, segments)
        if found is not None and found.axis != "z" and found.angle_deg < 45:
            raise DataError(
                f"{trial.meta.get('source', 'trial')}: after the static trial's axis conversion "
                f"({up}-up) the trial's body points {found.axis}; the two files use different "
                "axes. Fix: export both with the same axes (or pass --up-axis)"
            )
    if options.start_s is not None or options.end_s is not None:
        trial = trial.between(options.start_s, options.end_s)
    clusters = {
        m.name: [o.name for o in ms.markers if o.segment == m.segment and o.name != m.name]
        for m in ms.markers
    }
    trial, report = fill_gaps(trial, options.fill_gaps, options.max_gap_s, clusters)
    if options.lowpass_hz:
        trial, report = lowpass(trial, options.lowpass_hz, report=report)
    long_gaps = [g for g in report.left_open if g.start > 0 and g.stop < trial.n_frames]
    if long_gaps:
        worst = max(long_gaps, key=lambda g: g.length)
        warnings.add(
            f"{len(long_gaps)} gaps are not filled (longest: {worst.marker}, frames "
            f"{worst.start}-{worst.stop - 1}, {worst.length / trial.rate_hz:.2f} s); those markers "
            "are left out of those frames (--fill-gaps and --max-gap-s fill short gaps)"
        )
    return trial, static, report


ACROMION_HEIGHT_RATIO = 0.818  # acromion height / stature (Drillis & Contini; de Leva)
_FEET = ("foot_r", "foot_l", "toes_r", "toes_l")
_SHOULDERS = ("clavicle_r", "clavicle_l")


def _extent(z: FloatArray) -> float | None:
    """Median over frames of the vertical extent of the visible markers (z (N, M)), or
    None when no frame shows two of them."""
    seen = np.isfinite(z).sum(axis=1) >= 2
    if not seen.any():
        return None
    zs = z[seen]
    top = np.max(np.where(np.isfinite(zs), zs, -np.inf), axis=1)
    bottom = np.min(np.where(np.isfinite(zs), zs, np.inf), axis=1)
    return float(np.median(top - bottom))


def estimate_height(
    traj: MarkerTrajectories, ms: MarkerSet | None = None, warnings: _Warnings | None = None
) -> float:
    """Stature [m] from the markers (z-up).

    With head and foot markers: the median vertical extent of the markers (the head markers
    sit about a marker radius above the vertex, the foot markers about as far above the
    floor). Without head markers but with shoulders and feet: the acromion height over
    :data:`ACROMION_HEIGHT_RATIO` (a population ratio: a few centimetres either way), with
    a loud warning. Otherwise (or without a marker set to tell): refused, pass --height-m.
    """
    from mocapkit.body.anthropometry import HEIGHT_RANGE_M

    z = traj.positions[..., 2]
    if ms is not None:
        seg = {m.name: m.segment for m in ms.markers}
        cols = {s: [i for i, n in enumerate(traj.names) if seg.get(n) in s]
                for s in (("head",), _FEET, _SHOULDERS)}  # fmt: skip
        head, feet, shoulders = (cols[("head",)], cols[_FEET], cols[_SHOULDERS])
        if not feet or not (head or shoulders):
            lacking = "foot" if not feet else "head or shoulder"
            raise DataError(
                f"cannot estimate the stature: the trial has no {lacking} markers (the "
                "markers' height range would not be the body's); pass --height-m"
            )
        if not head:
            with np.errstate(invalid="ignore"):
                floor = np.nanmin(z[:, feet], axis=1)
                acromion = np.nanmean(z[:, shoulders], axis=1) - floor
            acromion = acromion[np.isfinite(acromion)]
            if acromion.size == 0:
                raise DataError(
                    "cannot estimate the stature: no frame shows a shoulder and a foot "
                    "marker together; pass --height-m"
                )
            h = float(np.median(acromion)) / ACROMION_HEIGHT_RATIO
            if warnings is not None:
                warnings.add(
                    f"NO HEAD MARKERS: the stature ({h:.3f} m) is estimated from the "
                    f"shoulder markers' height / {ACROMION_HEIGHT_RATIO} (a population ratio, "
                    "+-4 %); segment lengths and masses scale with it. Pass --height-m"
                )
            if not (HEIGHT_RANGE_M[0] <= h <= HEIGHT_RANGE_M[1]):
                raise DataError(
                    f"cannot estimate the stature from the shoulder markers ({h:.2f} m); "
                    "pass --height-m"
                )
            return h
    extent = _extent(z)
    if extent is None:
        raise DataError(
            "cannot estimate the stature: no frame shows two markers at once; pass --height-m"
        )
    h = extent
    if not (HEIGHT_RANGE_M[0] <= h <= HEIGHT_RANGE_M[1]):
        raise DataError(
            f"cannot estimate the stature from the markers (vertical extent {h:.2f} m); "
            "pass --height-m"
        )
    return h


def check_static_matches(
    static: MarkerTrajectories, trial: MarkerTrajectories, ms: MarkerSet, warnings: _Warnings
) -> None:
    """Markers on one rigid segment keep their distance: compare the static trial with the
    trial (median over frames); a mismatch means another subject or relabelled markers."""
    index_s = {n: i for i, n in enumerate(static.names)}
    index_t = {n: i for i, n in enumerate(trial.names)}
    by_seg: dict[str, list[str]] = {}
    for m in ms.markers:
        if m.name in index_s and m.name in index_t:
            by_seg.setdefault(m.segment, []).append(m.name)
    worst: tuple[float, str, str, float, float] | None = None
    for names in by_seg.values():
        for i, a in enumerate(names):
            for b in names[i + 1 :]:
                d_s = np.linalg.norm(static.marker(a) - static.marker(b), axis=1)
                d_t = np.linalg.norm(trial.marker(a) - trial.marker(b), axis=1)
                d_s, d_t = d_s[np.isfinite(d_s)], d_t[np.isfinite(d_t)]
                if d_s.size == 0 or d_t.size == 0:
                    continue
                ds, dt = float(np.median(d_s)), float(np.median(d_t))
                if worst is None or abs(ds - dt) > worst[0]:
                    worst = (abs(ds - dt), a, b, float(ds), float(dt))
    if worst is None or worst[0] <= RIGID_PAIR_TOLERANCE_M:
        return
    _, a, b, ds, dt = worst
    what = (
        f"markers {a} and {b} sit on one segment but are {ds * 1000:.0f} mm apart in the "
        f"static trial and {dt * 1000:.0f} mm in the trial"
    )
    if worst[0] > RIGID_PAIR_REFUSE_M:
        raise DataError(
            f"the static trial does not match the trial: {what}. Use the same subject's "
            "static trial (or fix swapped labels)"
        )
    warnings.add(
        f"the static trial and the trial differ: {what} (a marker moved between them, or "
        "skin motion); its registered offset may be off by that much"
    )


def check_static_still(static: MarkerTrajectories) -> None:
    """Refuse a static trial that moves (a walking trial given as the static one): its
    stillest 0.5 s would be scaled as a standing pose."""
    from mocapkit.body.scaling import STATIC_WINDOW_S, static_speed

    speed = static_speed(static.time, static.positions)
    if speed > STATIC_SPEED_REFUSE_M_S:
        raise DataError(
            f"{static.meta.get('source', 'static trial')}: not a static trial: its stillest "
            f"{STATIC_WINDOW_S:.1f} s still moves at {speed * 1000:.0f} mm/s (mean marker "
            "speed). Pass a recording of the subject standing still, or omit --static to "
            "estimate the limb lengths from the trial"
        )


def calibrate(
    static: MarkerTrajectories | None,
    trial: MarkerTrajectories,
    ms: MarkerSet,
    height_m: float,
    mass_kg: float,
    sex: Sex = "male",
) -> Subject:
    """A scaled subject from the static trial, or from the trial itself when there is none."""
    if static is not None:
        return scale_from_static(
            static.names, static.time, static.positions, ms, height_m, mass_kg, sex
        )
    from mocapkit.body.scaling import estimate_scales_from_motion

    return estimate_scales_from_motion(trial.names, trial.positions, ms, height_m, mass_kg, sex)


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
    human, ms = subject.human, subject.markerset
    tasks, notes = resolve_coordinate_tasks(human, ms.coordinate_tasks)
    for note in notes:
        log.info("%s", note)
    names = [n for n in trial.names if n in human.markers]
    unregistered = set(subject.report.get("unregistered_markers", ()))
    X = np.ascontiguousarray(trial.select(names).positions)
    weights = np.array([ms.spec(n).weight for n in names])
    if options.method == "osc":
        segment_of = {n: human.markers[n][0] for n in names}
        levels = make_levels(
            options.grouping, names, ms, segment_of, dict(zip(names, weights, strict=True)),
            human.segment_depth(),
        )  # fmt: skip
        tracked = [n for level in levels for n in level]
    else:
        levels = (tuple(n for n, w in zip(names, weights, strict=True) if w > 0),)
        tracked = list(levels[0])
    if not tracked:
        raise DataError("no marker left to track; check the marker set and the trial's labels")
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
    if not np.isfinite(result.coordinates[:, result.fitted_angles]).any():
        raise DataError(
            f"the {len(tracked)} tracked markers ({', '.join(tracked[:8])}"
            f"{' ...' if len(tracked) > 8 else ''}) determine no joint angle of the model: "
            "its pelvis and trunk stay free. Track more markers (--grouping paper puts the "
            "paper's levels above all the others; the default is single)"
        )
    if unregistered & set(tracked):
        warn.add(
            f"markers {', '.join(sorted(unregistered & set(tracked)))} were not in the static "
            "trial: their offsets are the marker set's generic guesses"
        )
    result.warnings[:] = list(warn)
    return result


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
    if static_path is not None and Path(static_path).resolve() == Path(trial_path).resolve():
        raise ConfigError(
            f"--static {static_path} is the trial itself; a static trial is a separate "
            "recording of the subject standing still. Pass it, or omit --static to estimate "
            "the limb lengths from the trial"
        )
    if markerset is None:
        ms = choose_markerset(trial, warn)
    else:
        ms = load_markerset(markerset)
    if ik_setup is not None:
        ms, opts = apply_ik_setup(ms, opts, ik_setup, warn)
    trial, static, cleaning = prepare(trial, static, ms, opts, warn)
    if static is not None:
        check_static_still(static)
        check_static_matches(static, trial, ms, warn)
    if height_m is None:
        n_before = len(warn)
        height_m = estimate_height(static if static is not None else trial, ms, warn)
        if len(warn) == n_before:
            warn.add(
                f"no --height-m given: {height_m:.3f} m estimated from the markers' extent "
                "(head to feet)"
            )
    if mass_kg is None:
        mass_kg = DEFAULT_MASS_KG
        warn.add(
            f"no --mass-kg given: {mass_kg:.0f} kg assumed for the segment masses (they set "
            "the simulated dynamics of direct marker control, not IK's angles)"
        )
    scale_static = static
    if static is not None and ms.description.startswith("assigned automatically"):
        warn.add(
            "the marker set was assigned automatically, so its markers have no known place "
            "on their segments to start a static registration from: the limb lengths and "
            "marker places are estimated from the trial's motion; the static trial gave the "
            "stature only"
        )
        scale_static = None
    subject = calibrate(scale_static, trial, ms, height_m, mass_kg, sex)
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
