"""Hypothesis strategies for rotations, including the hard cases near identity and near pi."""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

finite = st.floats(min_value=-1.0, max_value=1.0, allow_nan=False, allow_infinity=False)


@st.composite
def unit_vectors(draw: st.DrawFn) -> np.ndarray:
    v = np.array([draw(finite), draw(finite), draw(finite)])
    n = np.linalg.norm(v)
    if n < 1e-3:
        return np.array([0.0, 0.0, 1.0])
    return v / n


@st.composite
def rotation_angles(draw: st.DrawFn) -> float:
    """Angles in [0, pi], with extra weight on the neighbourhoods of 0 and pi."""
    kind = draw(st.sampled_from(["any", "near0", "nearpi"]))
    if kind == "near0":
        return draw(st.floats(min_value=0.0, max_value=1e-5))
    if kind == "nearpi":
        return np.pi - draw(st.floats(min_value=0.0, max_value=1e-5))
    return draw(st.floats(min_value=0.0, max_value=np.pi))


@st.composite
def unit_quats(draw: st.DrawFn) -> np.ndarray:
    axis = draw(unit_vectors())
    angle = draw(rotation_angles())
    q = np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])
    if draw(st.booleans()):
        q = -q
    return q


def same_rotation(q1: np.ndarray, q2: np.ndarray, tol: float) -> bool:
    """Compare quaternions up to sign."""
    return bool(np.all(1.0 - np.abs(np.sum(q1 * q2, axis=-1)) <= tol))
