"""Named robot arms: ``robot_arm("robonaut2-right")``, ``robot_arm("talos-right")``...

Robonaut 2 is our own model (``robonaut2.py``); Talos comes from the URDF shipped by the
``example-robot-data`` PyPI package (extra ``robots``), proving that any URDF arm works.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from mocapkit.errors import ConfigError
from mocapkit.robot.model import ArmModel
from mocapkit.robot.robonaut2 import robonaut2_arm
from mocapkit.robot.urdf import example_robot_data_path, load_urdf_arm

_TALOS_URDF = "robots/talos_data/robots/talos_reduced.urdf"


def _talos(side: str) -> ArmModel:
    sign = 1.0 if side == "left" else -1.0
    joints = [f"arm_{side}_{k}_joint" for k in range(1, 8)]
    # ready posture: upper arm slightly abducted, elbow bent 90 degrees, forearm forward
    q_ref = np.array([sign * 0.2, sign * 0.3, 0.0, -1.6, 0.0, 0.0, 0.0])
    return load_urdf_arm(
        example_robot_data_path(_TALOS_URDF),
        joints,
        base_frame="torso_2_link",
        ee_frame=f"gripper_{side}_base_link",
        q_ref=q_ref,
        name=f"talos-{side}",
    )


_ROBOTS: dict[str, Callable[[], ArmModel]] = {
    "robonaut2-right": lambda: robonaut2_arm("right"),
    "robonaut2-left": lambda: robonaut2_arm("left"),
    "talos-right": lambda: _talos("right"),
    "talos-left": lambda: _talos("left"),
}


def available_robots() -> list[str]:
    """Names accepted by :func:`robot_arm`."""
    return sorted(_ROBOTS)


def robot_arm(name: str) -> ArmModel:
    """Build a named arm model (a fresh copy each call)."""
    if name not in _ROBOTS:
        raise ConfigError(f"robot: unknown name {name!r}; choose one of {', '.join(_ROBOTS)}")
    return _ROBOTS[name]()
