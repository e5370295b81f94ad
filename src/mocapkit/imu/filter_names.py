"""The names of the built-in orientation filters, without importing them.

The command line offers these as choices before any filter (numba, scipy) is loaded;
``tests/imu/test_filter_contract.py`` checks that the list equals the registry's.
"""

from __future__ import annotations

BUILTIN_FILTERS: tuple[str, ...] = ("bachmann", "miller", "polaris", "polaris-body")
