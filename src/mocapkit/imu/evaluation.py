"""Evaluate an orientation filter on BROAD trials with BROAD's metric.

For each trial the filter starts fresh (initialised from the trial's first samples),
runs over the whole recording, and the errors are RMS values over the movement
phases (:mod:`mocapkit.imu.metrics`). In 9D no alignment is fitted; in 6D one
constant heading offset is removed before the total and heading errors.

Throughput is the fast path's single-thread speed as used: the wall time of
``filter.run(gyr, acc, mag)`` (validation and kernel) summed over the trials, after a
warm-up run that loads or compiles the numba kernels, so compilation is excluded.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from mocapkit.errors import ConfigError
from mocapkit.imu.filters.base import Backend, make_filter
from mocapkit.imu.metrics import OrientationErrors, orientation_rmse

if TYPE_CHECKING:
    from mocapkit.io.broad import BroadTrial

Mode = Literal["6d", "9d"]


@dataclass(frozen=True)
class TrialResult:
    name: str
    errors: OrientationErrors
    n_samples: int
    seconds: float  # wall time of the filter run


@dataclass(frozen=True)
class EvaluationResult:
    """Per-trial errors, their means (degrees at the edges) and the throughput."""

    filter: str
    mode: Mode
    trials: list[TrialResult]
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def samples_per_s(self) -> float:
        seconds = sum(t.seconds for t in self.trials)
        return sum(t.n_samples for t in self.trials) / seconds if seconds > 0 else float("nan")

    def mean_deg(self, which: str) -> float:
        return float(np.mean([np.degrees(getattr(t.errors, which)) for t in self.trials]))

    def as_json(self) -> dict[str, Any]:
        """The issue's JSON object: filter, mode, trials{name: errors}, means, samples_per_s."""
        return {
            "filter": self.filter,
            "mode": self.mode,
            "trials": {t.name: t.errors.as_degrees() for t in self.trials},
            "mean_total_deg": self.mean_deg("total"),
            "mean_inclination_deg": self.mean_deg("inclination"),
            "samples_per_s": self.samples_per_s,
        }


def _check_mode(mode: str) -> Mode:
    if mode not in ("6d", "9d"):
        raise ConfigError(f"mode: expected '6d' or '9d', got {mode!r}")
    return mode  # type: ignore[return-value]


def evaluate_trial(
    trial: BroadTrial,
    name: str,
    mode: Mode = "9d",
    backend: Backend = "fast",
    prepare: Callable[[BroadTrial], Any] | None = None,
    offline: bool = False,
    **params: Any,
) -> tuple[TrialResult, np.ndarray]:
    """Run filter ``name`` on one trial; returns the result and the (N, 4) estimates.

    ``prepare`` may return a modified ``ImuRecording`` (e.g. gyroscope bias removed);
    ``offline`` uses the filter's forward-backward mode (:func:`check_offline`).
    """
    mode = _check_mode(mode)
    imu = prepare(trial) if prepare is not None else trial.imu
    filt = make_filter(name, trial.rate_hz, backend, **params)
    mag = imu.mag if mode == "9d" else None
    start = time.perf_counter()
    q = (
        check_offline(filt, name).run_offline(imu.gyr, imu.acc, mag)
        if offline
        else filt.run(imu.gyr, imu.acc, mag)
    )
    seconds = time.perf_counter() - start
    errors = orientation_rmse(q, trial.reference.quat, trial.movement, align_heading=mode == "6d")
    return TrialResult(trial.name, errors, imu.n_samples, seconds), q


def check_offline(filt: Any, name: str) -> Any:
    """``filt`` if it has an offline (forward-backward) mode, else a ConfigError naming
    the filters that do."""
    if not callable(getattr(filt, "run_offline", None)):
        raise ConfigError(
            f"--offline: filter {name!r} has no offline mode; use polaris or polaris-body "
            "(forward-backward smoothing), or drop --offline"
        )
    return filt


def warm_up(name: str, backend: Backend = "fast", **params: Any) -> None:
    """Run the filter once on a few synthetic samples so numba kernels are loaded."""
    filt = make_filter(name, 100.0, backend, **params)
    acc = np.tile([0.0, 0.0, 9.81], (8, 1))
    mag = np.tile([0.0, 20.0, -40.0], (8, 1))
    filt.run(np.zeros((8, 3)), acc, mag)
    filt.run(np.zeros((8, 3)), acc)


def evaluate(
    trials: Iterable[BroadTrial],
    name: str,
    mode: Mode = "9d",
    backend: Backend = "fast",
    prepare: Callable[[BroadTrial], Any] | None = None,
    offline: bool = False,
    **params: Any,
) -> EvaluationResult:
    """Evaluate filter ``name`` on every trial (see the module docstring)."""
    mode = _check_mode(mode)
    if offline:
        check_offline(make_filter(name, 100.0, backend, **params), name)
    warm_up(name, backend, **params)
    results = [
        evaluate_trial(t, name, mode, backend, prepare, offline, **params)[0] for t in trials
    ]
    if not results:
        raise ConfigError("trials: nothing to evaluate")
    return EvaluationResult(name, mode, results, dict(params))
