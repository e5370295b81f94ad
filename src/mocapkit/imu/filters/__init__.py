"""Orientation filters. Importing this package registers the built-in filters."""

from mocapkit.imu.filters.base import (
    FilterParams,
    OrientationFilter,
    available_filters,
    make_filter,
    register_filter,
)
from mocapkit.imu.filters.polaris import Polaris, PolarisParams, PolarisState

__all__ = [
    "FilterParams",
    "OrientationFilter",
    "Polaris",
    "PolarisParams",
    "PolarisState",
    "available_filters",
    "make_filter",
    "register_filter",
]
