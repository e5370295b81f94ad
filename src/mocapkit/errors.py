"""Exception hierarchy: every error mocapkit raises derives from :class:`MocapkitError`.

Specific errors also inherit the matching built-in, so ``except ValueError``
in user code keeps working (``ShapeError`` is a ``ValueError``).
"""

from __future__ import annotations


class MocapkitError(Exception):
    """Root of all mocapkit errors."""


class ShapeError(MocapkitError, ValueError):
    """An array argument has the wrong shape. The message names the argument."""


class DataError(MocapkitError, ValueError):
    """Input data are invalid (NaN, non-monotonic time, wrong units...).

    The message names the field and the first offending sample, and says how to fix it.
    """


class FileFormatError(MocapkitError, ValueError):
    """A file cannot be parsed as the format it claims to be."""


class ConfigError(MocapkitError, ValueError):
    """A parameter or configuration value is out of range or inconsistent."""


class MissingDependencyError(MocapkitError, ImportError):
    """An optional dependency is not installed. The message gives the install hint."""


class ConvergenceError(MocapkitError, RuntimeError):
    """An iterative solve failed. Carries the problem and the last iterate."""
