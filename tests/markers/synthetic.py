"""Synthetic marker data with exact answers: a known model, markers and motion."""

from __future__ import annotations

import numpy as np

from mocapkit.body.human_model import HumanModel, build_human_model
from mocapkit.body.markersets import MarkerSet, load_markerset
from mocapkit.markers.kinematics import MarkerKinematics


def subject(
    height: float = 1.8, scales: dict[str, float] | None = None
) -> tuple[HumanModel, MarkerSet]:
    ms = load_markerset("gait2392")
    human = build_human_model(height, 75.0, "male", scales)
    human = human.with_markers(ms.placements(height, human.segment_scales))
    return human, ms


def motion(
    human: HumanModel, n: int = 40, rate: float = 60.0, amplitude: float = 0.3
) -> np.ndarray:
    """(n, nq) smooth walking-like motion within the limits (pelvis moving forward)."""
    t = np.arange(n) / rate
    Q = np.tile(human.neutral(), (n, 1))
    Q[:, 0] = 0.8 * t
    lo, hi = human.dof_limits()
    mid = 0.5 * (lo + hi)
    rng = np.random.default_rng(3)
    phase = rng.uniform(0, 2 * np.pi, len(lo))
    span = np.minimum(hi - lo, np.pi) * 0.5 * amplitude
    centre = np.clip(np.zeros_like(mid), lo + span, hi - span)
    Q[:, 7:] = centre + span * np.sin(2 * np.pi * 1.0 * t[:, None] + phase)
    for name in ("subtalar_angle_r", "mtp_angle_r", "subtalar_angle_l", "mtp_angle_l"):
        Q[:, human.dof_index(name) + 1] = 0.0
    return Q


def markers(human: HumanModel, names: list[str], Q: np.ndarray) -> np.ndarray:
    kin = MarkerKinematics(human, names)
    return np.array([kin.positions(q) for q in Q])
