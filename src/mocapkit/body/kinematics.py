"""Body kinematics from sensor orientations: the batch entry point and the streaming API.

Batch: :func:`body_angles` (``backend="fast"``: numba kernel over time; ``"reference"``:
numpy through mocapkit.geometry; they agree to 1e-9).

Streaming: :class:`BodyStream` is built once from a tree and a calibration, preallocates
every buffer, and turns one frame of sensor quaternions into joint angles with no Python
loop over joints (the teleoperation pipeline calls it at 100 Hz). Frame-by-frame output
equals the batch output: unwrapping, gimbal hold and dropout hold carry over in its state.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray, as_float_array, check_shape
from mocapkit.body import _kernels
from mocapkit.body.calibration import BodyCalibration
from mocapkit.body.joint_angles import (
    NEAR_GIMBAL_DEG,
    BodyAngles,
    coordinate_slots,
    joint_angles_reference,
    joint_tables,
    report_gimbal,
)
from mocapkit.body.segments import apply_calibration, sensor_array
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import ConfigError, ShapeError
from mocapkit.series import JointAngleSeries, OrientationSeries


@dataclass
class StreamState:
    """Checkpointable state of a :class:`BodyStream` (copy with ``copy.deepcopy``)."""

    last_q: FloatArray  # (S, 4) last valid sensor orientation
    last_t: FloatArray  # (S,) its time [s] (NaN: never seen)
    cont: FloatArray  # (S, 3) continuous (unwrapped) raw joint angles [rad]
    have_prev: np.ndarray  # (S,) bool
    last_third: FloatArray  # (S,) third angle before the last gimbal lock [rad]

    @classmethod
    def empty(cls, n_seg: int) -> StreamState:
        return cls(
            last_q=np.full((n_seg, 4), np.nan),
            last_t=np.full(n_seg, np.nan),
            cont=np.zeros((n_seg, 3)),
            have_prev=np.zeros(n_seg, dtype=np.bool_),
            last_third=np.zeros(n_seg),
        )


class BodyStream:
    """Per-frame body kinematics (see the module docstring).

    Args:
        tree: the sensor tree.
        calib: its calibration.
        dropout: ``"hold"`` (default for live use) holds a missing sensor's last
            orientation for ``max_hold_s``, then its segment and every joint touching it
            are NaN; ``"nan"`` marks them NaN at once.
    """

    def __init__(
        self,
        tree: SensorTree,
        calib: BodyCalibration,
        *,
        dropout: str = "hold",
        max_hold_s: float = 0.5,
    ) -> None:
        if dropout not in ("nan", "hold"):
            raise ConfigError(f"dropout: expected 'nan' or 'hold', got {dropout!r}")
        if not (np.isfinite(max_hold_s) and max_hold_s >= 0):
            raise ConfigError(
                f"max_hold_s: expected a non-negative time in seconds, got {max_hold_s}"
            )
        calib.check_tree(tree)
        self.tree = tree
        self.calib = calib
        self.sensor_names: tuple[str, ...] = tree.sensor_names
        self.segment_names: tuple[str, ...] = tree.segment_names
        self.coordinate_names: tuple[str, ...] = tree.coordinate_names
        self._index = {name: i for i, name in enumerate(self.sensor_names)}
        n = len(tree.segments)
        self._mount = np.ascontiguousarray(
            np.stack([calib.segments[s].q_sensor_segment for s in self.segment_names])
        )
        self._heading = np.ascontiguousarray(
            np.stack([calib.segments[s].q_heading for s in self.segment_names])
        )
        q_b, signs, offsets = joint_tables(tree)
        self._q_b = np.ascontiguousarray(q_b)
        self._signs = np.ascontiguousarray(signs)
        self._offsets = np.ascontiguousarray(offsets)
        self._parents = np.ascontiguousarray(tree.parent_index)
        self._q_wg = np.ascontiguousarray(calib.q_world_ground)
        seg_idx, ang_idx = coordinate_slots(tree)
        self._seg_idx, self._ang_idx = seg_idx, ang_idx
        self._hold = dropout == "hold"
        self._max_hold = float(max_hold_s)
        self._near_limit = float(np.deg2rad(90.0 - NEAR_GIMBAL_DEG))
        self._in = np.full((n, 4), np.nan)
        self._work = np.empty((4, 4))
        self.q_world_segment = np.full((n, 4), np.nan)
        """(S, 4) segment orientations of the last frame (NaN: unknown)."""
        self.angles = np.full(len(self.coordinate_names), np.nan)
        """(K,) joint angles of the last frame [rad] (the array :meth:`update` returns)."""
        self.stale = np.zeros(n, dtype=np.bool_)
        """(S,) sensors without a fresh sample in the last frame (held or missing)."""
        self.gimbal = np.zeros(n, dtype=np.bool_)
        """(S,) joints in gimbal lock in the last frame (third angle held)."""
        self.near_gimbal = np.zeros(n, dtype=np.bool_)
        self._keys_checked = -1
        self.state = StreamState.empty(n)

    # -- state ----------------------------------------------------------------------------------
    def get_state(self) -> StreamState:
        return copy.deepcopy(self.state)

    def set_state(self, state: StreamState) -> None:
        self.state = copy.deepcopy(state)

    def reset(self) -> None:
        self.state = StreamState.empty(len(self.segment_names))

    # -- per frame ------------------------------------------------------------------------------
    def _check_keys(self, quats: Mapping[str, Any]) -> None:
        unknown = [k for k in quats if k not in self._index]
        if unknown:
            raise ConfigError(
                f"unknown sensor name(s) {', '.join(map(repr, sorted(unknown)))} in the frame; "
                f"tree {self.tree.name!r} expects: {', '.join(map(repr, self.sensor_names))}. "
                "Map them with tree.with_sensor_names({segment: sensor})."
            )
        self._keys_checked = len(quats)

    def update(self, quats: Mapping[str, Any], t: float) -> FloatArray:
        """One frame: ``{sensor: q_world_sensor (4,)}`` at time ``t`` [s] -> joint angles (K,)
        [rad], written into (and returned as) :attr:`angles`. A sensor absent from the
        mapping or with a NaN quaternion counts as missing for this frame."""
        if len(quats) != self._keys_checked:
            self._check_keys(quats)
        buf = self._in
        buf.fill(np.nan)
        index = self._index
        try:
            for name, q in quats.items():
                buf[index[name]] = q
        except KeyError:
            self._check_keys(quats)
            raise
        except (ValueError, TypeError) as exc:
            raise ShapeError(
                f"sensor {name!r}: expected a quaternion [w, x, y, z] of shape (4,) ({exc})"
            ) from exc
        return self._run_frame(t)

    def update_array(self, q_world_sensor: Any, t: float) -> FloatArray:
        """One frame from an (S, 4) array in :attr:`sensor_names` order (NaN row: missing)."""
        q = np.asarray(q_world_sensor, dtype=np.float64)
        if q.shape != self._in.shape:
            raise ConfigError(
                f"q_world_sensor: expected shape {self._in.shape} (sensors "
                f"{', '.join(self.sensor_names)}), got {q.shape}"
            )
        self._in[...] = q
        return self._run_frame(t)

    def _run_frame(self, t: float) -> FloatArray:
        st = self.state
        _kernels.frame_kernel(
            self._in, float(t), self._mount, self._heading, self._q_b, self._parents,
            self._q_wg, self._signs, self._offsets, self._seg_idx, self._ang_idx,
            self._hold, self._max_hold, self._near_limit,
            st.last_q, st.last_t, st.cont, st.have_prev, st.last_third,
            self.q_world_segment, self.angles, self.stale, self.gimbal, self.near_gimbal,
            self._work,
        )  # fmt: skip
        return self.angles

    def invalid_coordinates(self) -> list[str]:
        """Names of the coordinates that are NaN in the last frame."""
        return [c for c, v in zip(self.coordinate_names, self.angles, strict=True) if v != v]

    # -- batch ------------------------------------------------------------------------------------
    def run(
        self, time: Any, q_world_sensor: Any
    ) -> tuple[FloatArray, FloatArray, dict[str, np.ndarray]]:
        """Frames (N,) [s] and (N, S, 4) -> joint angles (N, K), segment orientations
        (N, S, 4) and per-frame flags ``{"stale", "gimbal", "near_gimbal"}`` (N, S),
        continuing from the current state (``run(a); run(b)`` equals ``run(a + b)``)."""
        t = as_float_array(time, "time")
        check_shape(t, "time", None)
        q = as_float_array(q_world_sensor, "q_world_sensor")
        check_shape(q, "q_world_sensor", t.shape[0], len(self.sensor_names), 4)
        n, s = t.shape[0], len(self.sensor_names)
        out = np.empty((n, len(self.coordinate_names)))
        q_seg = np.empty((n, s, 4))
        flags = {k: np.zeros((n, s), dtype=np.bool_) for k in ("stale", "gimbal", "near_gimbal")}
        st = self.state
        _kernels.batch_kernel(
            np.ascontiguousarray(q), t, self._mount, self._heading, self._q_b, self._parents,
            self._q_wg, self._signs, self._offsets, self._seg_idx, self._ang_idx,
            self._hold, self._max_hold, self._near_limit,
            st.last_q, st.last_t, st.cont, st.have_prev, st.last_third,
            q_seg, out, flags["stale"], flags["gimbal"], flags["near_gimbal"],
        )  # fmt: skip
        return out, q_seg, flags


def body_angles(
    tree: SensorTree,
    calib: BodyCalibration,
    orientations: Mapping[str, OrientationSeries],
    *,
    dropout: str = "nan",
    max_hold_s: float = 0.5,
    backend: str = "fast",
    name: str = "joint_angles",
) -> tuple[BodyAngles, dict[str, OrientationSeries]]:
    """Joint angles and segment orientations from ``{sensor: q_world_sensor series}``.

    All series must share one time base (:func:`mocapkit.body.timebase.align_orientations`).
    ``dropout="nan"`` marks joints touching a missing sensor NaN; ``"hold"`` holds the
    sensor's last orientation for up to ``max_hold_s`` first (counts in ``BodyAngles.held``).
    """
    if backend not in ("fast", "reference"):
        raise ConfigError(f"backend: expected 'fast' or 'reference', got {backend!r}")
    time, q_sensor, held = sensor_array(tree, orientations, dropout=dropout, max_hold_s=max_hold_s)
    if backend == "reference":
        q_seg = apply_calibration(tree, calib, q_sensor)
        segments = {
            s.name: OrientationSeries(time, q_seg[:, i], name=s.name)
            for i, s in enumerate(tree.segments)
        }
        result = joint_angles_reference(tree, segments, calib.q_world_ground, name=name)
        return BodyAngles(
            result.angles, result.gimbal, result.near_gimbal, result.missing, held
        ), segments
    # holding was done above (same rule as the kernel's), so the kernel only sees NaN gaps
    stream = BodyStream(tree, calib, dropout="nan")
    values, q_seg, flags = stream.run(time, q_sensor)
    segments = {
        s.name: OrientationSeries(time, q_seg[:, i], name=s.name)
        for i, s in enumerate(tree.segments)
    }
    exact, close = report_gimbal(tree, flags["gimbal"], flags["near_gimbal"], time)
    coords = tree.coordinate_names
    missing = {c: int(np.isnan(values[:, k]).sum()) for k, c in enumerate(coords)}
    angles = JointAngleSeries(time, coords, values, name=name)
    return BodyAngles(angles, exact, close, {c: n for c, n in missing.items() if n}, held), segments
