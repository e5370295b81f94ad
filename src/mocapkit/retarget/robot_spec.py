"""A humanoid for retargeting is one YAML file: where its URDF is, which human segment
drives which robot frame (weights), its reference posture, its feet.

Packaged robots live in ``mocapkit/data/humanoids/*.yaml``; any ``--robot`` takes their
name or a YAML path. Layout::

    name: g1
    description: Unitree G1, 29 DOF
    urdf: example-robot-data:robots/g1_description/urdf/g1_29dof_rev_1_0.urdf
    floating_base: true            # false: the root frame is fixed (upper bodies)
    q_ref: {right_elbow_joint: -1.0}   # reference posture ~ the human standing, arms down
    keypoints:                     # human segment -> robot frame
      pelvis: {frame: pelvis, position: 1.0, orientation: 1.0}
      hand_r: {frame: right_wrist_yaw_link, position: 1.0, orientation: 0.1}
    feet:                          # human foot segment -> robot frame, sole below it [m]
      foot_r: {frame: right_ankle_roll_link, sole: [0.0, 0.0, -0.035]}
    velocity_limit_default: 3.0    # rad/s where the URDF gives none (0 or >= 100)

Frames, joints and segments are checked when the robot is built: a wrong name is refused
naming the frame and the frames the URDF has.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError, FileFormatError, MissingDependencyError

HUMAN_SEGMENTS = (
    "pelvis", "abdomen", "thorax", "neck", "head",
    "upper_arm_r", "forearm_r", "hand_r", "upper_arm_l", "forearm_l", "hand_l",
    "thigh_r", "shank_r", "foot_r", "toes_r", "thigh_l", "shank_l", "foot_l", "toes_l",
)  # fmt: skip
# Which human segment a keypoint hangs from (for per-bone scaling).
HUMAN_PARENT = {
    "abdomen": "pelvis", "thorax": "abdomen", "neck": "thorax", "head": "neck",
    "upper_arm_r": "thorax", "forearm_r": "upper_arm_r", "hand_r": "forearm_r",
    "upper_arm_l": "thorax", "forearm_l": "upper_arm_l", "hand_l": "forearm_l",
    "thigh_r": "pelvis", "shank_r": "thigh_r", "foot_r": "shank_r", "toes_r": "foot_r",
    "thigh_l": "pelvis", "shank_l": "thigh_l", "foot_l": "shank_l", "toes_l": "foot_l",
}  # fmt: skip
LIMBS = {  # a robot map must drive each limb it names at its end
    "right arm": ("upper_arm_r", "forearm_r", "hand_r"),
    "left arm": ("upper_arm_l", "forearm_l", "hand_l"),
    "right leg": ("thigh_r", "shank_r", "foot_r"),
    "left leg": ("thigh_l", "shank_l", "foot_l"),
}
DEFAULT_VELOCITY_LIMIT = 3.0  # rad/s


@dataclass(frozen=True)
class Keypoint:
    segment: str  # human segment
    frame: str  # robot frame
    position: float  # weight of the position task
    orientation: float  # weight of the orientation task


@dataclass(frozen=True)
class Foot:
    segment: str
    frame: str
    sole: FloatArray  # (3,) sole point in the frame [m]


@dataclass(frozen=True)
class RobotSpec:
    name: str
    urdf: Path
    floating_base: bool
    keypoints: tuple[Keypoint, ...]
    feet: tuple[Foot, ...] = ()
    q_ref: Mapping[str, float] = field(default_factory=dict)
    root_frame: str | None = None  # fixed base: the frame the human's thorax drives
    velocity_limit_default: float = DEFAULT_VELOCITY_LIMIT
    description: str = ""
    source: str = ""

    def keypoint(self, segment: str) -> Keypoint | None:
        for k in self.keypoints:
            if k.segment == segment:
                return k
        return None


def packaged_robots() -> dict[str, Path]:
    """{name: YAML path} of the robots shipped with mocapkit."""
    base = resources.files("mocapkit") / "data" / "humanoids"
    return {Path(str(p)).stem: Path(str(p)) for p in base.iterdir() if str(p).endswith(".yaml")}


def _resolve_urdf(text: str, yaml_path: Path) -> Path:
    """``example-robot-data:REL``, ``shared:REL`` (``../shared/data`` or
    ``MOCAPKIT_SHARED_DATA``), an absolute path, or a path relative to the YAML file."""
    if text.startswith("example-robot-data:"):
        from mocapkit.robot.urdf import example_robot_data_path

        return example_robot_data_path(text.split(":", 1)[1])
    if text.startswith("shared:"):
        rel = text.split(":", 1)[1]
        roots = [os.environ.get("MOCAPKIT_SHARED_DATA", ""), "../shared/data", "shared/data"]
        here = Path(__file__).resolve()
        roots += [str(p / "shared" / "data") for p in here.parents[:5]]
        for r in roots:
            if r and (Path(r) / rel).is_file():
                return (Path(r) / rel).resolve()
        raise MissingDependencyError(
            f"urdf {text!r}: not found; it is not shipped with mocapkit (licence). Put the "
            "shared data beside the checkout or set MOCAPKIT_SHARED_DATA to its data/ "
            "directory"
        )
    p = Path(os.path.expandvars(os.path.expanduser(text)))
    return p if p.is_absolute() else (yaml_path.parent / p)


def load_robot_spec(name_or_path: str | Path) -> RobotSpec:
    """A packaged robot by name (``mocapkit robot list``) or a YAML file."""
    import yaml

    packaged = packaged_robots()
    text = str(name_or_path)
    if text in packaged:
        path = packaged[text]
    else:
        path = Path(text)
        if not path.is_file():
            raise ConfigError(
                f"robot: {text!r} is neither a packaged robot ({', '.join(sorted(packaged))}) "
                "nor a YAML file"
            )
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise FileFormatError(f"{path}: not valid YAML ({exc})") from exc
    if not isinstance(data, Mapping):
        raise FileFormatError(f"{path}: expected a mapping at the top level")
    return spec_from_dict(data, path)


def _vec(v: Any, where: str, n: int = 3) -> FloatArray:
    a = np.asarray(v, dtype=float)
    if a.shape != (n,) or not np.isfinite(a).all():
        raise ConfigError(f"{where}: expected {n} finite numbers, got {v!r}")
    return a


def spec_from_dict(data: Mapping[str, Any], path: Path) -> RobotSpec:
    for key in ("name", "urdf", "keypoints"):
        if key not in data:
            raise ConfigError(f"{path}: missing '{key}'")
    kps = []
    raw = data["keypoints"]
    if not isinstance(raw, Mapping) or not raw:
        raise ConfigError(f"{path}: 'keypoints' must map human segments to robot frames")
    for seg, entry in raw.items():
        if seg not in HUMAN_SEGMENTS:
            raise ConfigError(
                f"{path}: keypoints.{seg}: not a human segment; choose from "
                f"{', '.join(HUMAN_SEGMENTS)}"
            )
        if not isinstance(entry, Mapping) or "frame" not in entry:
            raise ConfigError(f"{path}: keypoints.{seg}: needs 'frame'")
        pw, ow = float(entry.get("position", 1.0)), float(entry.get("orientation", 0.0))
        if pw < 0 or ow < 0 or pw + ow == 0:
            raise ConfigError(f"{path}: keypoints.{seg}: weights must be >= 0, not both 0")
        kps.append(Keypoint(str(seg), str(entry["frame"]), pw, ow))
    names = {k.segment for k in kps}
    for limb, segs in LIMBS.items():
        present = [s for s in segs if s in names]
        if present and segs[-1] not in names:
            raise ConfigError(
                f"{path}: the {limb} is driven at {', '.join(present)} but not at its end "
                f"({segs[-1]}): add keypoints.{segs[-1]} or remove the limb"
            )
    feet = []
    for seg, entry in (data.get("feet") or {}).items():
        if seg not in ("foot_r", "foot_l"):
            raise ConfigError(f"{path}: feet.{seg}: expected foot_r or foot_l")
        feet.append(
            Foot(str(seg), str(entry["frame"]), _vec(entry.get("sole", [0, 0, 0]), f"feet.{seg}"))
        )
    floating = bool(data.get("floating_base", True))
    if floating and "pelvis" not in names:
        raise ConfigError(f"{path}: a floating-base robot needs keypoints.pelvis")
    if not floating and (not data.get("root_frame") or "pelvis" in names):
        raise ConfigError(
            f"{path}: a fixed-base robot names its root frame (root_frame: LINK, which stands "
            "for the human pelvis) and has no keypoints.pelvis"
        )
    return RobotSpec(
        name=str(data["name"]),
        urdf=_resolve_urdf(str(data["urdf"]), path),
        floating_base=floating,
        keypoints=tuple(kps),
        feet=tuple(feet),
        q_ref={str(k): float(v) for k, v in (data.get("q_ref") or {}).items()},
        root_frame=data.get("root_frame"),
        velocity_limit_default=float(data.get("velocity_limit_default", DEFAULT_VELOCITY_LIMIT)),
        description=str(data.get("description", "")),
        source=str(path),
    )
