"""mocapkit: human motion capture to humanoid joint angles and robot commands.

Conventions (docs/conventions.md): quaternions are Hamilton ``[w, x, y, z]``;
``q_world_sensor`` maps sensor-frame vectors into the world; the world is z-up
(ENU); SI units and radians inside, degrees only at the edges; time is the
first axis.
"""

from mocapkit.errors import MocapkitError

__version__ = "0.1.0"
__all__ = ["MocapkitError", "__version__"]
