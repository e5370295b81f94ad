"""Segment inertial parameters scaled to a subject's stature and mass.

Source: P. de Leva, "Adjustments to Zatsiorsky-Seluyanov's segment inertia parameters",
J. Biomechanics 29(9), 1996, Table 4 (young adults; male mean stature 1741 mm, female
1735 mm). Per segment: length between its two end points [mm at the mean stature],
mass [% of body mass], centre of mass [% of length from the first end point] and radii
of gyration about the sagittal (x, antero-posterior), transverse (y, medio-lateral) and
longitudinal (z) axes [% of length].

End points: VERT vertex, CERV cervicale (C7), XYPH xiphion, OMPH omphalion, MIDH mid-hip
(between the hip joint centres), SJC/EJC/WJC/HJC/KJC shoulder/elbow/wrist/hip/knee joint
centres, MET3 third metacarpale, LMAL lateral malleolus, HEEL, TTIP tip of the longest toe.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from mocapkit.errors import ConfigError

Sex = Literal["male", "female"]

# name: (first end, second end, length_mm, mass_pct, com_pct, r_sag, r_trans, r_long)
_DE_LEVA: dict[Sex, dict[str, tuple[str, str, float, float, float, float, float, float]]] = {
    "male": {
        "head": ("VERT", "CERV", 242.9, 6.94, 59.76, 36.2, 37.6, 31.2),
        "upper_trunk": ("CERV", "XYPH", 242.1, 15.96, 29.99, 71.6, 45.4, 65.9),
        "middle_trunk": ("XYPH", "OMPH", 215.5, 16.33, 45.02, 48.2, 38.3, 46.8),
        "lower_trunk": ("OMPH", "MIDH", 145.7, 11.17, 61.15, 61.5, 55.1, 58.7),
        "upper_arm": ("SJC", "EJC", 281.7, 2.71, 57.72, 28.5, 26.9, 15.8),
        "forearm": ("EJC", "WJC", 268.9, 1.62, 45.74, 27.6, 26.5, 12.1),
        "hand": ("WJC", "MET3", 86.2, 0.61, 79.00, 62.8, 51.3, 40.1),
        "thigh": ("HJC", "KJC", 422.2, 14.16, 40.95, 32.9, 32.9, 14.9),
        "shank": ("KJC", "LMAL", 434.0, 4.33, 44.59, 25.5, 24.9, 10.3),
        "foot": ("HEEL", "TTIP", 258.1, 1.37, 44.15, 25.7, 24.5, 12.4),
    },
    "female": {
        "head": ("VERT", "CERV", 243.7, 6.68, 58.94, 33.0, 35.9, 31.8),
        "upper_trunk": ("CERV", "XYPH", 228.0, 15.45, 20.77, 74.6, 50.2, 71.8),
        "middle_trunk": ("XYPH", "OMPH", 205.3, 14.65, 45.12, 43.3, 35.4, 41.5),
        "lower_trunk": ("OMPH", "MIDH", 181.5, 12.47, 49.20, 43.3, 40.2, 44.4),
        "upper_arm": ("SJC", "EJC", 275.1, 2.55, 57.54, 27.8, 26.0, 14.8),
        "forearm": ("EJC", "WJC", 264.3, 1.38, 45.59, 26.1, 25.7, 9.4),
        "hand": ("WJC", "MET3", 78.0, 0.56, 74.74, 53.1, 45.4, 33.5),
        "thigh": ("HJC", "KJC", 368.5, 14.78, 36.12, 36.9, 36.4, 16.2),
        "shank": ("KJC", "LMAL", 432.3, 4.81, 44.16, 27.1, 26.7, 9.3),
        "foot": ("HEEL", "TTIP", 228.3, 1.29, 40.14, 29.9, 27.9, 13.9),
    },
}
_MEAN_STATURE_MM: dict[Sex, float] = {"male": 1741.0, "female": 1735.0}

# Plausible adult ranges; outside them the tables do not apply (and a unit mistake is likely).
HEIGHT_RANGE_M = (1.0, 2.4)
MASS_RANGE_KG = (20.0, 250.0)


@dataclass(frozen=True)
class SegmentParameters:
    """One de Leva segment scaled to a subject.

    Attributes:
        length: distance between the end points [m].
        mass: [kg].
        com_fraction: centre of mass from the first end point, as a fraction of ``length``.
        radii: radii of gyration about the sagittal (x), transverse (y) and longitudinal (z)
            axes through the centre of mass [m].
    """

    name: str
    first: str
    second: str
    length: float
    mass: float
    com_fraction: float
    radii: tuple[float, float, float]

    def inertia(self, length_scale: float = 1.0) -> np.ndarray:
        """Principal moments (3,) [kg m^2] about the centre of mass, for a segment whose
        length is scaled by ``length_scale`` (radii scale with length)."""
        r = np.asarray(self.radii) * length_scale
        return self.mass * r**2


def check_subject(height_m: float, mass_kg: float) -> None:
    """Raise ConfigError unless stature and mass are plausible for an adult, in SI units."""
    lo, hi = HEIGHT_RANGE_M
    if not (np.isfinite(height_m) and lo <= height_m <= hi):
        hint = " (looks like centimetres or millimetres: give metres)" if height_m > hi else ""
        raise ConfigError(f"height_m: expected {lo}-{hi} m, got {height_m}{hint}")
    lo, hi = MASS_RANGE_KG
    if not (np.isfinite(mass_kg) and lo <= mass_kg <= hi):
        raise ConfigError(f"mass_kg: expected {lo}-{hi} kg, got {mass_kg}")


def segment_parameters(
    height_m: float, mass_kg: float, sex: Sex = "male"
) -> dict[str, SegmentParameters]:
    """de Leva's segments for a subject: lengths scaled by stature, masses by body mass."""
    if sex not in _DE_LEVA:
        raise ConfigError(f"sex: expected 'male' or 'female', got {sex!r}")
    check_subject(height_m, mass_kg)
    k = height_m * 1000.0 / _MEAN_STATURE_MM[sex]
    out: dict[str, SegmentParameters] = {}
    for name, (a, b, length_mm, mass_pct, com_pct, rs, rt, rl) in _DE_LEVA[sex].items():
        length = length_mm * 1e-3 * k
        out[name] = SegmentParameters(
            name=name,
            first=a,
            second=b,
            length=length,
            mass=mass_kg * mass_pct / 100.0,
            com_fraction=com_pct / 100.0,
            radii=(rs / 100.0 * length, rt / 100.0 * length, rl / 100.0 * length),
        )
    return out


def total_mass_fraction(sex: Sex = "male") -> float:
    """Sum of the mass percentages, counting limbs twice (100 % up to table rounding)."""
    limbs = {"upper_arm", "forearm", "hand", "thigh", "shank", "foot"}
    return sum(v[3] * (2 if k in limbs else 1) for k, v in _DE_LEVA[sex].items()) / 100.0
