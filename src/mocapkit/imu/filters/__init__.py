"""Orientation filters. Importing this package registers the built-in filters."""

from mocapkit.imu.filters import bachmann, miller  # noqa: F401  (register the filters)
from mocapkit.imu.filters.base import (
    FilterParams,
    FilterState,
    OrientationFilter,
    RunReport,
    SensorSaturationWarning,
    TimeGapWarning,
    available_filters,
    make_filter,
    register_filter,
)
from mocapkit.imu.filters.polaris import Polaris, PolarisParams, PolarisState

__all__ = [
    "FilterParams",
    "FilterState",
    "OrientationFilter",
    "Polaris",
    "PolarisParams",
    "PolarisState",
    "RunReport",
    "SensorSaturationWarning",
    "TimeGapWarning",
    "available_filters",
    "make_filter",
    "register_filter",
]
