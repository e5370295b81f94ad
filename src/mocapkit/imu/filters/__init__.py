"""Orientation filters. Importing this package registers the built-in filters."""

from mocapkit.imu.filters.base import (
    FilterParams,
    OrientationFilter,
    available_filters,
    make_filter,
    register_filter,
)

__all__ = [
    "FilterParams",
    "OrientationFilter",
    "available_filters",
    "make_filter",
    "register_filter",
]
