"""Human joint angles -> robot joint angles through a validated YAML map (any robot).

Per robot joint: ``q = offset + sign * scale * human`` [rad], clipped to the map's limits
(which must lie within the robot's), or a fixed value. Example (see
``mocapkit/data/robots/*.yaml``)::

    robot: robonaut2-right        # a name from mocapkit.robot.registry, or:
    # urdf: {path: arm.urdf, base_frame: torso, ee_frame: hand, joints: [j1, j2, ...]}
    joints:
      r2/right_arm/joint0: {human: arm_flex_r, sign: 1, offset_deg: 0}
      r2/right_arm/joint3: {human: elbow_flex_r, sign: -1, limits_deg: [-150, 0]}
      r2/right_arm/wrist/yaw: {fixed_deg: 0}

Every robot joint must be mapped or fixed. Errors name the file, the joint, the field and
the fix.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError, DataError, FileFormatError
from mocapkit.robot.model import ArmModel
from mocapkit.series import JointAngleSeries

_JOINT_KEYS = {"human", "sign", "scale", "offset_deg", "limits_deg", "fixed_deg"}


@dataclass(frozen=True)
class JointMapping:
    """One robot joint: ``offset + sign * scale * human`` within ``[lower, upper]`` [rad],
    or ``fixed`` [rad] when ``human`` is None."""

    robot_joint: str
    human: str | None
    sign: float = 1.0
    scale: float = 1.0
    offset: float = 0.0
    lower: float = -np.inf
    upper: float = np.inf
    fixed: float | None = None


@dataclass(frozen=True)
class UrdfSpec:
    """A robot given by its URDF file (instead of a registry name)."""

    path: Path
    base_frame: str
    ee_frame: str
    joints: tuple[str, ...]


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not np.isfinite(value):
        raise ConfigError(f"{where}: expected a finite number, got {value!r}")
    return float(value)


class RetargetMap:
    """A validated human-to-robot joint map; see the module docstring."""

    def __init__(
        self,
        mappings: Sequence[JointMapping],
        robot: str | None = None,
        urdf: UrdfSpec | None = None,
        source: str = "<map>",
    ) -> None:
        if (robot is None) == (urdf is None):
            raise ConfigError(f"{source}: give exactly one of 'robot' (a name) and 'urdf'")
        self.mappings = tuple(mappings)
        self.robot = robot
        self.urdf = urdf
        self.source = source
        names = [m.robot_joint for m in self.mappings]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ConfigError(f"{source}: robot joint(s) mapped twice: {', '.join(dup)}")

    # -- construction ----------------------------------------------------------------------
    @classmethod
    def from_yaml(cls, path: str | Path) -> RetargetMap:
        p = Path(path)
        try:
            data = yaml.safe_load(p.read_text())
        except yaml.YAMLError as exc:
            raise FileFormatError(f"{p}: not valid YAML ({exc})") from exc
        return cls.from_dict(data, source=str(p), base_dir=p.parent)

    @classmethod
    def from_dict(
        cls, data: Any, source: str = "<map>", base_dir: Path | None = None
    ) -> RetargetMap:
        if not isinstance(data, Mapping):
            raise ConfigError(f"{source}: expected a mapping with 'robot' and 'joints'")
        unknown = set(data) - {"robot", "urdf", "joints"}
        if unknown:
            raise ConfigError(
                f"{source}: unknown key(s) {', '.join(sorted(unknown))}; "
                "allowed: robot, urdf, joints"
            )
        urdf = None
        if "urdf" in data:
            u = data["urdf"]
            need = {"path", "base_frame", "ee_frame", "joints"}
            if not isinstance(u, Mapping) or not need <= set(u):
                raise ConfigError(f"{source}: urdf: needs {', '.join(sorted(need))}")
            upath = Path(str(u["path"]))
            if not upath.is_absolute() and base_dir is not None:
                upath = base_dir / upath
            urdf = UrdfSpec(
                upath, str(u["base_frame"]), str(u["ee_frame"]), tuple(map(str, u["joints"]))
            )
        joints = data.get("joints")
        if not isinstance(joints, Mapping) or not joints:
            raise ConfigError(f"{source}: 'joints' must map robot joint names to entries")
        mappings = [cls._entry(str(k), v, source) for k, v in joints.items()]
        robot = data.get("robot")
        return cls(mappings, robot=None if robot is None else str(robot), urdf=urdf, source=source)

    @staticmethod
    def _entry(joint: str, entry: Any, source: str) -> JointMapping:
        where = f"{source}: joints.{joint}"
        if not isinstance(entry, Mapping):
            raise ConfigError(f"{where}: expected a mapping like {{human: elbow_flex_r, sign: 1}}")
        unknown = set(entry) - _JOINT_KEYS
        if unknown:
            raise ConfigError(
                f"{where}: unknown key(s) {', '.join(sorted(unknown))}; "
                f"allowed: {', '.join(sorted(_JOINT_KEYS))}"
            )
        if "fixed_deg" in entry:
            if "human" in entry:
                raise ConfigError(f"{where}: give either 'human' or 'fixed_deg', not both")
            fixed = np.radians(_number(entry["fixed_deg"], f"{where}.fixed_deg"))
            return JointMapping(joint, None, fixed=float(fixed))
        if "human" not in entry:
            raise ConfigError(f"{where}: needs 'human' (a coordinate name) or 'fixed_deg'")
        sign = _number(entry.get("sign", 1), f"{where}.sign")
        if sign not in (1.0, -1.0):
            raise ConfigError(f"{where}.sign: expected 1 or -1, got {entry.get('sign')!r}")
        scale = _number(entry.get("scale", 1.0), f"{where}.scale")
        if scale <= 0:
            raise ConfigError(
                f"{where}.scale: expected a positive factor, got {scale}; use sign: -1 to "
                "reverse a joint"
            )
        offset = float(np.radians(_number(entry.get("offset_deg", 0.0), f"{where}.offset_deg")))
        lower, upper = -np.inf, np.inf
        if "limits_deg" in entry:
            lim = entry["limits_deg"]
            if not isinstance(lim, Sequence) or isinstance(lim, str) or len(lim) != 2:
                raise ConfigError(f"{where}.limits_deg: expected [lower, upper] in degrees")
            lower = float(np.radians(_number(lim[0], f"{where}.limits_deg[0]")))
            upper = float(np.radians(_number(lim[1], f"{where}.limits_deg[1]")))
            if lower >= upper:
                raise ConfigError(
                    f"{where}.limits_deg: lower {lim[0]} must be below upper {lim[1]}"
                )
        return JointMapping(joint, str(entry["human"]), sign, scale, offset, lower, upper)

    # -- binding to a robot ----------------------------------------------------------------
    def build_arm(self) -> ArmModel:
        """The robot this map is written for (registry name or URDF)."""
        if self.urdf is not None:
            from mocapkit.robot.urdf import load_urdf_arm

            u = self.urdf
            return load_urdf_arm(u.path, u.joints, u.base_frame, u.ee_frame)
        from mocapkit.robot.registry import robot_arm

        assert self.robot is not None
        return robot_arm(self.robot)

    def check_arm(self, arm: ArmModel) -> None:
        """Validate the map against an arm: every joint mapped once, limits inside."""
        mapped = {m.robot_joint for m in self.mappings}
        unknown = sorted(mapped - set(arm.joint_names))
        if unknown:
            raise ConfigError(
                f"{self.source}: {', '.join(unknown)} not joint(s) of {arm.name}; its joints: "
                f"{', '.join(arm.joint_names)}"
            )
        missing = [j for j in arm.joint_names if j not in mapped]
        if missing:
            raise ConfigError(
                f"{self.source}: robot joint(s) not mapped: {', '.join(missing)}; map each to "
                "a human coordinate or hold it with fixed_deg"
            )
        for m in self.mappings:
            i = arm.joint_index(m.robot_joint)
            lo, hi = arm.lower[i], arm.upper[i]
            where = f"{self.source}: joints.{m.robot_joint}"
            if m.fixed is not None and not lo <= m.fixed <= hi:
                raise ConfigError(
                    f"{where}.fixed_deg: {np.degrees(m.fixed):.1f} is outside the robot's "
                    f"limits [{np.degrees(lo):.1f}, {np.degrees(hi):.1f}] deg"
                )
            if np.isfinite(m.lower) and (m.lower < lo - 1e-9 or m.upper > hi + 1e-9):
                raise ConfigError(
                    f"{where}.limits_deg: [{np.degrees(m.lower):.1f}, {np.degrees(m.upper):.1f}]"
                    f" exceeds the robot's [{np.degrees(lo):.1f}, {np.degrees(hi):.1f}] deg; "
                    "narrow it or drop it"
                )

    @property
    def human_names(self) -> tuple[str, ...]:
        """Human coordinates the map reads."""
        return tuple(m.human for m in self.mappings if m.human is not None)

    # -- application -----------------------------------------------------------------------
    def compile(self, arm: ArmModel, human_names: Sequence[str]) -> CompiledMap:
        """Bind to an arm and a column order of human coordinates (fast per-frame use)."""
        self.check_arm(arm)
        names = list(human_names)
        missing = [h for h in self.human_names if h not in names]
        if missing:
            raise DataError(
                f"{self.source}: human coordinate(s) {', '.join(missing)} not in the joint "
                f"angles; available: {', '.join(names)}"
            )
        n = arm.n
        src = np.full(n, -1, dtype=np.intp)
        gain = np.zeros(n)
        offset = np.zeros(n)
        lower = arm.lower.copy()
        upper = arm.upper.copy()
        for m in self.mappings:
            i = arm.joint_index(m.robot_joint)
            if m.fixed is not None:
                offset[i] = m.fixed
                continue
            assert m.human is not None
            src[i] = names.index(m.human)
            gain[i] = m.sign * m.scale
            offset[i] = m.offset
            lower[i] = max(lower[i], m.lower)
            upper[i] = min(upper[i], m.upper)
        return CompiledMap(arm.joint_names, src, gain, offset, lower, upper)

    def apply(self, series: JointAngleSeries, arm: ArmModel) -> tuple[JointAngleSeries, FloatArray]:
        """Robot joint angles for a human series; also the (N, n) bool mask of clipped
        values. NaN human frames give NaN robot frames (the session holds on them)."""
        cm = self.compile(arm, series.names)
        q, clipped = cm.apply(series.values)
        return JointAngleSeries(series.time, arm.joint_names, q, name=arm.name), clipped


@dataclass(frozen=True)
class CompiledMap:
    """A map bound to an arm and a human column order: ``apply(values)`` on (N, k) or (k,)."""

    robot_joints: tuple[str, ...]
    src: np.ndarray  # (n,) column of the human coordinate, -1 for fixed joints
    gain: FloatArray
    offset: FloatArray
    lower: FloatArray
    upper: FloatArray

    def apply(self, human: Any) -> tuple[FloatArray, np.ndarray]:
        h = np.asarray(human, dtype=float)
        single = h.ndim == 1
        h2 = h[None, :] if single else h
        picked = np.where(self.src >= 0, h2[:, np.maximum(self.src, 0)], 0.0)
        q = self.offset + self.gain * picked
        with np.errstate(invalid="ignore"):
            clipped = (q < self.lower) | (q > self.upper)
        q = np.clip(q, self.lower, self.upper)  # NaN stays NaN
        return (q[0], clipped[0]) if single else (q, clipped)


def packaged_map(name: str) -> RetargetMap:
    """A map shipped with mocapkit, e.g. ``packaged_map("robonaut2-right")``."""
    from importlib import resources

    fname = name.replace("-", "_") + ".yaml"
    ref = resources.files("mocapkit") / "data" / "robots" / fname
    if not ref.is_file():
        raise ConfigError(f"no packaged retarget map {name!r} (looked for data/robots/{fname})")
    return RetargetMap.from_dict(yaml.safe_load(ref.read_text()), source=f"mocapkit:{fname}")
