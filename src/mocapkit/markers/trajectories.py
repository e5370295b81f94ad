"""Labelled 3-D marker trajectories: the value every marker stage passes on.

Time is the first axis; positions are metres in the frame of the file until
:func:`mocapkit.markers.conventions.to_z_up` says otherwise (``meta["up_axis"]``);
a NaN row (all three components) marks a marker that is not visible in that frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray, as_float_array, check_shape
from mocapkit.errors import DataError, ShapeError


def _frozen(arr: FloatArray) -> FloatArray:
    arr.setflags(write=False)
    return arr


def check_whole_rows(
    pos: FloatArray, names: tuple[str, ...], where: str = "positions", offset: int = 0
) -> None:
    """Refuse a marker partly NaN in a frame of ``pos`` (N, M, 3) (frames counted from
    ``offset``): a missing marker is NaN in all three coordinates."""
    finite = np.isfinite(pos)
    partial = finite.any(axis=2) & ~finite.all(axis=2)
    if partial.any():
        f, m = np.argwhere(partial)[0]
        raise DataError(
            f"{where}: marker {names[m]!r} is partly NaN at frame {offset + int(f)}; mark a "
            "missing marker with all three coordinates NaN"
        )


@dataclass(frozen=True)
class MarkerTrajectories:
    """Marker positions over time.

    Attributes:
        time: (N,) sample times [s], strictly increasing.
        positions: (N, M, 3) marker positions [m]; a marker not visible in a frame is NaN
            in all three components.
        names: M unique marker labels.
        meta: provenance (source file, declared units, axis conversion, cleaning steps).
    """

    time: FloatArray
    positions: FloatArray
    names: tuple[str, ...]
    meta: dict[str, Any] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        time = as_float_array(self.time, "time")
        check_shape(time, "time", None)
        if not np.isfinite(time).all():
            i = int(np.flatnonzero(~np.isfinite(time))[0])
            raise DataError(f"time: non-finite time stamp at frame {i}; fix the file's time column")
        if time.size > 1 and (np.diff(time) <= 0).any():
            i = int(np.flatnonzero(np.diff(time) <= 0)[0])
            raise DataError(
                f"time: not strictly increasing at frame {i + 1} ({time[i]:.6f} s then "
                f"{time[i + 1]:.6f} s); sort the frames and drop duplicates"
            )
        names = tuple(str(n) for n in self.names)
        pos = as_float_array(self.positions, "positions")
        check_shape(pos, "positions", time.shape[0], len(names), 3)
        seen: set[str] = set()
        for n in names:
            if not n.strip():
                raise ShapeError("names: empty marker label; label every marker")
            if n in seen:
                raise DataError(f"names: marker {n!r} appears twice; labels must be unique")
            seen.add(n)
        check_whole_rows(pos, names)
        pos[~np.isfinite(pos).all(axis=2)] = np.nan
        object.__setattr__(self, "time", _frozen(time))
        object.__setattr__(self, "positions", _frozen(pos))
        object.__setattr__(self, "names", names)

    # -- shape -----------------------------------------------------------------------------
    @property
    def n_frames(self) -> int:
        return int(self.time.shape[0])

    @property
    def n_markers(self) -> int:
        return len(self.names)

    @property
    def rate_hz(self) -> float:
        """Frame rate [Hz]: ``meta["rate_hz"]`` when the file declares it, else 1 / median dt."""
        declared = self.meta.get("rate_hz")
        if declared:
            return float(declared)
        if self.n_frames < 2:
            raise DataError("need at least 2 frames to know the frame rate")
        return float(1.0 / np.median(np.diff(self.time)))

    @property
    def visible(self) -> np.ndarray:
        """(N, M) bool: marker visible in frame."""
        return np.asarray(np.isfinite(self.positions[..., 0]))

    # -- access ----------------------------------------------------------------------------
    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise DataError(
                f"marker {name!r} not in trajectories; available: {', '.join(self.names)}"
            ) from None

    def marker(self, name: str) -> FloatArray:
        """(N, 3) positions of one marker."""
        return self.positions[:, self.index(name)]

    def select(self, names: Sequence[str]) -> MarkerTrajectories:
        """A new set holding only ``names`` (in that order)."""
        idx = [self.index(n) for n in names]
        return MarkerTrajectories(
            self.time, self.positions[:, idx], tuple(names), meta=dict(self.meta)
        )

    def slice(self, start: int, stop: int | None = None) -> MarkerTrajectories:
        """Frames ``start:stop``."""
        sl = slice(start, stop)
        return MarkerTrajectories(
            self.time[sl], self.positions[sl], self.names, meta=dict(self.meta)
        )

    def between(self, t0: float | None, t1: float | None) -> MarkerTrajectories:
        """Frames with ``t0 <= time <= t1`` (either bound may be None)."""
        keep = np.ones(self.n_frames, dtype=bool)
        if t0 is not None:
            keep &= self.time >= t0 - 1e-9
        if t1 is not None:
            keep &= self.time <= t1 + 1e-9
        if not keep.any():
            raise DataError(
                f"no frame between {t0} s and {t1} s; the trial spans "
                f"{self.time[0]:.3f}-{self.time[-1]:.3f} s"
            )
        idx = np.flatnonzero(keep)
        return self.slice(int(idx[0]), int(idx[-1]) + 1)

    def with_positions(
        self, positions: Any, meta_update: dict[str, Any] | None = None
    ) -> MarkerTrajectories:
        """The same markers and times with new positions (e.g. after cleaning)."""
        meta = dict(self.meta)
        meta.update(meta_update or {})
        return MarkerTrajectories(self.time, positions, self.names, meta=meta)
