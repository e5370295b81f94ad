"""mocapkit: human motion capture to humanoid joint angles and robot commands.

Conventions (docs/conventions.md): quaternions are Hamilton ``[w, x, y, z]``;
``q_world_sensor`` maps sensor-frame vectors into the world; the world is z-up
(ENU); SI units and radians inside, degrees only at the edges; time is the
first axis.
"""

from typing import Any

from mocapkit.errors import MocapkitError

__version__ = "0.1.0"

# The common path (mocapkit.api), imported on first use so `import mocapkit` stays light.
_API = (
    "BodyMotion",
    "Reconstruction",
    "RobotMotion",
    "body_angles",
    "make_filter",
    "read_c3d",
    "read_imu",
    "read_trc",
    "reconstruct",
    "retarget",
)


def __getattr__(name: str) -> Any:
    if name in _API:
        from mocapkit import api

        return getattr(api, name)
    raise AttributeError(f"module 'mocapkit' has no attribute {name!r}")


__all__ = ["MocapkitError", "__version__", *_API]
