"""Length units as files declare them (C3D ``POINT:UNITS``, TRC ``Units``)."""

from __future__ import annotations

from mocapkit.errors import FileFormatError

_TO_METRES = {
    "mm": 1e-3,
    "millimeters": 1e-3,
    "millimetres": 1e-3,
    "cm": 1e-2,
    "centimeters": 1e-2,
    "centimetres": 1e-2,
    "m": 1.0,
    "meters": 1.0,
    "metres": 1.0,
}


def length_scale(unit: str, where: str) -> float:
    """Factor that converts ``unit`` to metres; ``where`` names the file/field in errors."""
    key = unit.strip().lower()
    try:
        return _TO_METRES[key]
    except KeyError:
        raise FileFormatError(
            f"{where}: unknown length unit {unit!r}; expected one of mm, cm, m. Fix: pass "
            "the file's unit (--units mm|cm|m on the command line, units=... in Python)"
        ) from None
