"""What a reconstruction's figures and warnings are computed from, as sums that add up
piece by piece: a trial reconstructed in pieces (:mod:`mocapkit.markers.streamed`) reports
the same figures and the same warnings as the whole trial at once
(:class:`mocapkit.markers.result.ReconstructionResult`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.markers.bounds import POORLY_DETERMINED_DEG_PER_MM, BoundReport

if TYPE_CHECKING:
    from mocapkit.markers.result import ReconstructionResult


def _add_counts(a: dict[str, int], b: Mapping[str, int]) -> dict[str, int]:
    out = dict(a)
    for k, n in b.items():
        out[k] = out.get(k, 0) + int(n)
    return out


@dataclass
class Coverage:
    """Per reported coordinate (K): determined in some frame / in every frame, frames
    numerically unobserved; frames without a visible tracked marker (count, first and
    last time); frames near gimbal lock per joint; frames with a capped bound; poorly
    determined frames per coordinate."""

    names: tuple[str, ...]
    frames: int = 0
    ever: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    always: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    unobserved: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    blind: int = 0
    blind_first_s: float | None = None
    blind_last_s: float | None = None
    gimbal: dict[str, int] = field(default_factory=dict)
    capped_frames: int = 0
    poorly: dict[str, int] = field(default_factory=dict)

    @classmethod
    def of(
        cls,
        cnames: Sequence[str],
        structural: np.ndarray,
        det: np.ndarray,
        gimbal: Mapping[str, np.ndarray],
        report: BoundReport,
        t: FloatArray,
        blind: np.ndarray,
    ) -> Coverage:
        """One piece's coverage from its (N, K) determined masks and the bound report."""
        idx = np.flatnonzero(blind)
        col = {c: k for k, c in enumerate(cnames)}
        return cls(
            names=tuple(cnames),
            frames=int(det.shape[0]),
            ever=np.asarray(det.any(axis=0)),
            always=np.asarray(det.all(axis=0)),
            unobserved=(structural & report.unobserved).sum(axis=0).astype(np.int64),
            blind=int(idx.size),
            blind_first_s=float(t[idx[0]]) if idx.size else None,
            blind_last_s=float(t[idx[-1]]) if idx.size else None,
            gimbal={j: int((close & det[:, col[j]]).sum()) for j, close in gimbal.items()},
            capped_frames=int(report.capped.any(axis=1).sum()),
            poorly=dict(report.poorly_determined),
        )

    def merge(self, later: Coverage) -> Coverage:
        """This piece followed by ``later``."""
        if self.frames == 0:
            return later
        return Coverage(
            names=self.names,
            frames=self.frames + later.frames,
            ever=self.ever | later.ever,
            always=self.always & later.always,
            unobserved=self.unobserved + later.unobserved,
            blind=self.blind + later.blind,
            blind_first_s=self.blind_first_s
            if self.blind_first_s is not None
            else later.blind_first_s,
            blind_last_s=later.blind_last_s
            if later.blind_last_s is not None
            else self.blind_last_s,
            gimbal=_add_counts(self.gimbal, later.gimbal),
            capped_frames=self.capped_frames + later.capped_frames,
            poorly=_add_counts(self.poorly, later.poorly),
        )

    def warnings(self) -> list[str]:
        """What the outputs leave out or cannot vouch for, in words."""
        out = []
        never = [c for k, c in enumerate(self.names) if not self.ever[k]]
        if never:
            out.append(
                f"{len(never)} coordinates are not determined by any tracked marker and are "
                f"left out of the outputs: {', '.join(never)}"
            )
        partial = [c for k, c in enumerate(self.names) if self.ever[k] and not self.always[k]]
        if partial:
            out.append(
                f"coordinates {', '.join(partial[:10])}{' ...' if len(partial) > 10 else ''} "
                "are undetermined (NaN) in some frames where their markers are missing"
            )
        counts = [(c, int(self.unobserved[k])) for k, c in enumerate(self.names)]
        worst = sorted((kv for kv in counts if kv[1]), key=lambda kv: -kv[1])[:8]
        if worst:
            out.append(
                "numerically undetermined, so NaN there (the visible markers leave a "
                "direction of them unobserved, e.g. one marker for several DOFs): "
                + ", ".join(f"{c} in {n} frames" for c, n in worst)
            )
        if self.blind:
            out.append(
                f"{self.blind} of {self.frames} frames have no visible tracked marker (first "
                f"at t = {self.blind_first_s:.3f} s, last at t = {self.blind_last_s:.3f} s): "
                "the pose is held there and they have no marker error and no error bound "
                "(NaN in the per-frame series, left out of marker_rms_mm and the other "
                "figures)"
            )
        for joint, n_close in self.gimbal.items():
            if n_close:
                out.append(
                    f"{joint} within 10 deg of +-90 deg in {n_close} frames (gimbal lock of "
                    "OpenSim's rotation order): the other two angles of that joint are "
                    "ill-defined there (the model's own DOFs in q are not)"
                )
        if self.capped_frames:
            out.append(
                f"the joint-error bound (eq. 15) exceeded a joint's range in "
                f"{self.capped_frames} frames and is capped at the range there (the "
                "linearisation is meaningless that far)"
            )
        if self.poorly:
            worst_p = sorted(self.poorly.items(), key=lambda kv: -kv[1])[:6]
            out.append(
                "poorly determined by the visible markers (more than "
                f"{POORLY_DETERMINED_DEG_PER_MM:g} deg per mm of marker error): "
                + ", ".join(f"{d} in {n} frames" for d, n in worst_p)
                + "; their joint-error bounds rest on an ill-conditioned fit"
            )
        return out


@dataclass
class MetricsTally:
    """The figures of ``markers reconstruct --json`` summed piece by piece
    (:meth:`ReconstructionResult.metrics` is one piece's)."""

    frames: int = 0
    elapsed_s: float = 0.0
    rms_sum: float = 0.0
    rms_count: int = 0
    marker_max: float | None = None
    bound_max: float | None = None
    total_max: float | None = None
    has_total: bool = False

    def add(self, r: ReconstructionResult, markers: Sequence[str] | None = None) -> None:
        rms = r.frame_rms(markers)
        seen = np.isfinite(rms)
        e = r._errors_of(markers)
        self.frames += r.n_frames
        self.elapsed_s += r.elapsed_s
        self.rms_sum += float(rms[seen].sum())
        self.rms_count += int(seen.sum())
        self.marker_max = _max(self.marker_max, e)
        self.bound_max = _max(self.bound_max, np.abs(r.coordinate_bound[:, r.fitted_angles]))
        if r.bound is not None and r.bound.total is not None:
            self.has_total = True
            self.total_max = _max(self.total_max, r.bound.total[:, r.fitted_angles])

    def metrics(self) -> dict[str, Any]:
        def rounded(x: float | None, digits: int) -> float | None:
            return None if x is None else round(float(x), digits)

        fps = self.frames / self.elapsed_s if self.elapsed_s > 0 else float("inf")
        has_max = self.rms_count > 0 and self.marker_max is not None
        out: dict[str, Any] = {
            "frames": self.frames,
            "solve_fps": round(float(fps), 1),
            "marker_rms_mm": rounded(
                self.rms_sum / self.rms_count * 1000 if self.rms_count else None, 2
            ),
            "marker_max_mm": rounded(
                self.marker_max * 1000 if self.marker_max is not None and has_max else None, 2
            ),
            "joint_error_bound_deg_max": rounded(
                np.degrees(self.bound_max) if self.bound_max is not None else None, 3
            ),
        }
        if self.has_total:
            out["joint_error_total_bound_deg_max"] = rounded(
                np.degrees(self.total_max) if self.total_max is not None else None, 3
            )
        return out


def _max(current: float | None, values: FloatArray) -> float | None:
    fin = values[np.isfinite(values)]
    if fin.size == 0:
        return current
    m = float(fin.max())
    return m if current is None else max(current, m)
