"""A 25-joint, 48-DOF human skeleton built programmatically with Pinocchio.

Joints (anatomical, parent -> child segment):

============== ====================== ===================================================
joint           segments               degrees of freedom (Pinocchio joints, in order)
============== ====================== ===================================================
root            world -> pelvis        free-flyer (6)
lumbar          pelvis -> abdomen      abdomen_extension, abdomen_bending, abdomen_rotation
thorax          abdomen -> thorax      thorax_extension, thorax_bending, thorax_rotation
neck            thorax -> neck         cervical_extension, cervical_bending, cervical_rotation
head            neck -> head           head_extension
sternoclav_s    thorax -> clavicle_s   sc_elevation_s, sc_protraction_s
shoulder_s      clavicle_s -> upper_arm_s  shoulder_flexion_s, shoulder_adduction_s,
                                       shoulder_rotation_s
elbow_s         upper_arm_s -> ulna_s  elbow_flex_s
forearm_s       ulna_s -> forearm_s    pro_sup_s
wrist_s         forearm_s -> hand_s    wrist_flex_s, wrist_dev_s
hip_s           pelvis -> thigh_s      hip_flexion_s, hip_adduction_s, hip_rotation_s
knee_s          thigh_s -> shank_s     knee_angle_s
ankle_s         shank_s -> talus_s     ankle_angle_s
subtalar_s      talus_s -> foot_s      subtalar_angle_s
mtp_s           foot_s -> toes_s       mtp_angle_s
============== ====================== ===================================================

(s = r, l.) Every rotational DOF is its own Pinocchio revolute joint
(``JointModelRevoluteUnaligned``) named like the coordinate, so ``q[7:]`` holds the
anatomical angles [rad] and limits are boxes; only the last DOF of a joint carries the
child segment's inertia.

Frames: at the neutral configuration every segment frame is parallel to the world
(x forward, y left, z up) with its origin at the segment's proximal joint centre
(pelvis: the mid-point between the hip joint centres). Axes, order and signs of the
DOFs follow OpenSim's Rajagopal (2015) model, which the body (IMU) side uses, converted
from OpenSim's y-up body frames (x fwd, y up, z right) by ``a_ours = (a_x, -a_z, a_y)``:
hip flexion/adduction/rotation (positive = flexion, adduction, internal rotation),
``knee_angle`` positive in flexion about Rajagopal's walker-knee axis (gait2392's knee
turns about an axis 4 deg away and is negative in flexion), the oblique ankle,
subtalar and mtp axes (gait2392's = Rajagopal's), the elbow's oblique flexion axis and the
forearm's pronation axis (Rajagopal's ``elbow_r`` / ``radioulnar_r``, the pronation axis
made orthogonal to the elbow axis as the body side decomposes them), the wrist's flexion
then deviation. Shoulders follow the hip's convention.

Names: a DOF carries an OpenSim name only where it means what OpenSim's coordinate
means (hips, knees, ankles, subtalar, mtp, ``elbow_flex``, ``pro_sup``, ``wrist_flex``,
``wrist_dev``). The spine, neck and shoulder have more joints than Rajagopal's (who has
one ``back`` joint, no neck, and no shoulder girdle), so their DOFs have their own names
(``abdomen_*``, ``thorax_*``, ``cervical_*``, ``head_extension``, ``sc_*``, ``shoulder_*``)
and OpenSim's ``lumbar_*`` (thorax on pelvis), ``neck_*`` (head on thorax) and ``arm_*``
(upper arm on thorax) are computed from them (:mod:`mocapkit.markers.coordinates`).

Geometry: segment lengths from de Leva (1996) scaled by stature; offsets de Leva does
not give (hip-centre spacing, lumbar offset, ankle/subtalar/mtp geometry, foot centre
of mass) from the gait2392 generic model (a 1.80 m subject) scaled by stature / 1.80 m;
shoulder girdle from typical adult proportions (sternoclavicular joint 7 cm anterior
and 3 cm below C7, shoulder centres 0.2 x stature apart, for a 1.75 m subject).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.anthropometry import Sex, segment_parameters
from mocapkit.errors import ConfigError

_DEG = np.pi / 180.0
_OPENSIM_HEIGHT_M = 1.80  # stature of the gait2392 generic model


@dataclass(frozen=True)
class Dof:
    """One revolute degree of freedom: unit axis in the joint (= parent segment) frame."""

    name: str
    axis: tuple[float, float, float]
    lower_deg: float
    upper_deg: float


@dataclass(frozen=True)
class JointSpec:
    """An anatomical joint: where the child segment attaches and how it can turn."""

    name: str
    parent: str
    child: str
    position: tuple[float, float, float]  # in the parent segment frame [m], unscaled
    dofs: tuple[Dof, ...]


@dataclass(frozen=True)
class SegmentInertia:
    mass: float  # [kg]
    com: tuple[float, float, float]  # in the segment frame [m], unscaled
    moments: tuple[float, float, float]  # principal moments about the CoM [kg m^2], unscaled


def _side_sign(side: str) -> float:
    return -1.0 if side == "r" else 1.0  # y is left


# Rajagopal (2015) right elbow flexion (in the humerus) and pronation (in the ulna) axes in
# OpenSim's body frames (x fwd, y up, z right), the numbers of the body presets' elbow_r.
_ELBOW_AXIS_OPENSIM = (0.226, 0.0223, 0.9739)
_PRO_SUP_AXIS_OPENSIM = (0.0564, 0.9984, 0.002)
KNEE_FLEXION_MAX_DEG = 160.0
# Rajagopal's walker_knee_r flexion axis (in the femur; 4 deg from gait2392's pure z, and
# pointing the other way: knee_angle is positive in flexion), as the body presets' tibia_r.
_KNEE_AXIS_OPENSIM = (0.0, -0.0707, -0.9975)


def _to_ours(a: tuple[float, float, float], m: float) -> np.ndarray:
    """A right-side axis in OpenSim's body frame -> our frame (``(x, -z, y)``), mirrored to
    the left side (``m = -1``: x and y of the axis negated in OpenSim's frame, as the
    body presets' ``_l`` joints)."""
    x, y, z = a[0] * m, a[1] * m, a[2]
    v = np.array([x, -z, y])
    return v / np.linalg.norm(v)


def _axis(a: tuple[float, float, float], m: float) -> tuple[float, float, float]:
    v = _to_ours(a, m)
    return (float(v[0]), float(v[1]), float(v[2]))


def _elbow_axis(m: float) -> tuple[float, float, float]:
    return _axis(_ELBOW_AXIS_OPENSIM, m)


def _pro_sup_axis(m: float) -> tuple[float, float, float]:
    """Rajagopal's pronation axis made orthogonal to the elbow axis (Gram-Schmidt; 2.1 deg
    away), so that elbow then pronation is exactly what the body side's ``elbow_r`` joint
    decomposes (flexion, an unreported middle angle of zero, pronation)."""
    e = np.asarray(_elbow_axis(m))
    p = _to_ours(_PRO_SUP_AXIS_OPENSIM, m)
    p = p - (p @ e) * e
    p /= np.linalg.norm(p)
    return (float(p[0]), float(p[1]), float(p[2]))


def _joints(height_m: float, sex: Sex) -> list[JointSpec]:
    """The skeleton's joints for a subject of ``height_m`` (before segment scaling)."""
    p = segment_parameters(height_m, 70.0, sex)  # lengths do not depend on mass
    h, k = height_m, height_m / _OPENSIM_HEIGHT_M
    L = {name: s.length for name, s in p.items()}
    ey, ex, ez = (0.0, -1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)
    spine = [
        JointSpec(
            "lumbar",
            "pelvis",
            "abdomen",
            (-0.031 * k, 0.0, L["lower_trunk"]),
            (
                Dof("abdomen_extension", ey, -70, 45),
                Dof("abdomen_bending", ex, -40, 40),
                Dof("abdomen_rotation", ez, -45, 45),
            ),
        ),
        JointSpec(
            "thorax",
            "abdomen",
            "thorax",
            (0.0, 0.0, L["middle_trunk"]),
            (
                Dof("thorax_extension", ey, -60, 40),
                Dof("thorax_bending", ex, -30, 30),
                Dof("thorax_rotation", ez, -40, 40),
            ),
        ),
        JointSpec(
            "neck",
            "thorax",
            "neck",
            (-0.018 * k, 0.0, L["upper_trunk"]),
            (
                Dof("cervical_extension", ey, -60, 70),
                Dof("cervical_bending", ex, -45, 45),
                Dof("cervical_rotation", ez, -80, 80),
            ),
        ),
        JointSpec(
            "head",
            "neck",
            "head",
            (0.02 * k, 0.0, 0.4 * L["head"]),
            (Dof("head_extension", ey, -30, 30),),
        ),
    ]
    out = list(spine)
    for s in ("r", "l"):
        y = _side_sign(s)
        m = -y  # +1 on the right: mirrors axes whose sign flips between sides
        out += [
            JointSpec(
                f"sternoclav_{s}",
                "thorax",
                f"clavicle_{s}",
                (0.040 * h, y * 0.009 * h, L["upper_trunk"] - 0.017 * h),
                (
                    Dof(f"sc_elevation_{s}", (-m, 0.0, 0.0), -40, 45),
                    Dof(f"sc_protraction_{s}", (0.0, 0.0, m), -40, 40),
                ),
            ),
            JointSpec(
                f"shoulder_{s}",
                f"clavicle_{s}",
                f"upper_arm_{s}",
                (-0.040 * h, y * 0.091 * h, -0.015 * h),
                (
                    Dof(f"shoulder_flexion_{s}", ey, -90, 180),
                    Dof(f"shoulder_adduction_{s}", (m, 0.0, 0.0), -120, 45),
                    Dof(f"shoulder_rotation_{s}", (0.0, 0.0, m), -90, 100),
                ),
            ),
            JointSpec(
                f"elbow_{s}",
                f"upper_arm_{s}",
                f"ulna_{s}",
                (0.0, 0.0, -L["upper_arm"]),
                (Dof(f"elbow_flex_{s}", _elbow_axis(m), -5, 155),),
            ),
            JointSpec(
                f"forearm_{s}",
                f"ulna_{s}",
                f"forearm_{s}",
                (0.0, 0.0, 0.0),
                (Dof(f"pro_sup_{s}", _pro_sup_axis(m), -90, 180),),
            ),
            JointSpec(
                f"wrist_{s}",
                f"forearm_{s}",
                f"hand_{s}",
                (0.0, 0.0, -L["forearm"]),
                (
                    Dof(f"wrist_flex_{s}", ey, -75, 80),
                    Dof(f"wrist_dev_{s}", (m, 0.0, 0.0), -25, 45),
                ),
            ),
            JointSpec(
                f"hip_{s}",
                "pelvis",
                f"thigh_{s}",
                (0.0, y * 0.0835 * k, 0.0),
                (
                    Dof(f"hip_flexion_{s}", ey, -40, 130),
                    Dof(f"hip_adduction_{s}", (m, 0.0, 0.0), -50, 35),
                    Dof(f"hip_rotation_{s}", (0.0, 0.0, m), -60, 60),
                ),
            ),
            JointSpec(
                f"knee_{s}",
                f"thigh_{s}",
                f"shank_{s}",
                (0.0, 0.0, -L["thigh"]),
                # 160 deg: deep squatting and kneeling reach 150-160 deg (Hemmerich et al.
                # 2006, high range of motion activities); at 135 both IK and direct marker
                # control pinned CMU 85_12's knees at the limit for 240 frames
                (Dof(f"knee_angle_{s}", _axis(_KNEE_AXIS_OPENSIM, m), -10, KNEE_FLEXION_MAX_DEG),),
            ),
            JointSpec(
                f"ankle_{s}",
                f"shank_{s}",
                f"talus_{s}",
                (0.0, 0.0, -L["shank"]),
                (Dof(f"ankle_angle_{s}", (-0.105014 * m, -0.979126, -0.174022 * m), -60, 50),),
            ),
            JointSpec(
                f"subtalar_{s}",
                f"talus_{s}",
                f"foot_{s}",
                (-0.04877 * k, y * 0.00792 * k, -0.04195 * k),
                (Dof(f"subtalar_angle_{s}", (0.78718 * m, 0.120949, 0.604747 * m), -35, 35),),
            ),
            JointSpec(
                f"mtp_{s}",
                f"foot_{s}",
                f"toes_{s}",
                (0.1788 * k, y * 0.00108 * k, -0.002 * k),
                (Dof(f"mtp_angle_{s}", (-0.580954 * m, -0.813936, 0.0), -40, 70),),
            ),
        ]
    # Pinocchio needs a depth-first order (every subtree a contiguous range of joints):
    # spine, both arms (children of the thorax), then both legs (children of the pelvis).
    arms = [
        j
        for j in out[len(spine) :]
        if not j.parent.startswith(("pelvis", "thigh", "shank", "talus", "foot"))
    ]
    legs = [j for j in out[len(spine) :] if j not in arms]
    return spine + arms + legs


def _inertias(height_m: float, mass_kg: float, sex: Sex) -> dict[str, SegmentInertia]:
    """Mass, CoM and principal moments per segment (de Leva; small segments documented)."""
    p = segment_parameters(height_m, mass_kg, sex)
    k = height_m / _OPENSIM_HEIGHT_M
    girdle = 0.006 * mass_kg  # clavicle + scapula per side, taken from the upper trunk

    def seg(
        name: str, com_z: float, mass: float | None = None, com_x: float = 0.0
    ) -> SegmentInertia:
        sp = p[name]
        m = sp.mass if mass is None else mass
        mom = m * np.asarray(sp.radii) ** 2
        return SegmentInertia(m, (com_x, 0.0, com_z), (float(mom[0]), float(mom[1]), float(mom[2])))

    lt, mt, ut, hd = p["lower_trunk"], p["middle_trunk"], p["upper_trunk"], p["head"]
    out = {
        "pelvis": seg("lower_trunk", (1.0 - lt.com_fraction) * lt.length),
        "abdomen": seg("middle_trunk", (1.0 - mt.com_fraction) * mt.length, com_x=0.035 * k),
        "thorax": seg(
            "upper_trunk",
            (1.0 - ut.com_fraction) * ut.length,
            mass=ut.mass - 2 * girdle,
            com_x=0.035 * k,
        ),
        "neck": seg("head", 0.2 * hd.length, mass=0.2 * hd.mass),
        "head": seg("head", 0.25 * hd.length, mass=0.8 * hd.mass, com_x=0.02 * k),
    }
    for s in ("r", "l"):
        y = _side_sign(s)
        rc = 0.05 * height_m  # radius of gyration of the girdle [m]
        out[f"clavicle_{s}"] = SegmentInertia(
            girdle,
            (-0.02 * height_m, y * 0.045 * height_m, -0.008 * height_m),
            (girdle * rc**2,) * 3,
        )
        out[f"ulna_{s}"] = SegmentInertia(0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))  # massless
        for name in ("upper_arm", "forearm", "hand", "thigh", "shank"):
            sp = p[name]
            out[f"{name}_{s}"] = seg(name, -sp.com_fraction * sp.length)
        foot = p["foot"]
        out[f"talus_{s}"] = SegmentInertia(
            0.05 * foot.mass,
            (0.0, 0.0, 0.0),
            (0.05 * foot.mass * (0.02 * k) ** 2,) * 3,
        )
        mf = 0.80 * foot.mass
        out[f"foot_{s}"] = SegmentInertia(
            mf,
            (0.100 * k, 0.0, 0.030 * k),
            (mf * foot.radii[0] ** 2, mf * foot.radii[1] ** 2, mf * foot.radii[2] ** 2),
        )
        mt_ = 0.15 * foot.mass
        out[f"toes_{s}"] = SegmentInertia(
            mt_,
            (0.035 * k, -y * 0.018 * k, 0.006 * k),
            (mt_ * (0.03 * k) ** 2,) * 3,
        )
    return out


@dataclass(frozen=True)
class HumanModel:
    """A scaled skeleton: the Pinocchio model plus the names and maps the rest of mocapkit uses.

    Attributes:
        model: Pinocchio model (free-flyer root, one revolute joint per DOF). Marker frames,
            when attached (:meth:`with_markers`), are ``OP_FRAME``\\s named ``marker:NAME``.
        height_m, mass_kg, sex: the subject.
        segment_scales: per-segment length scale factors applied on top of stature.
        joints: the anatomical joints (unscaled positions).
        segment_joint: segment -> Pinocchio joint id that carries it.
        dof_names: the 42 revolute DOF names (= Pinocchio joint names), ``q[7:]`` order.
        markers: marker name -> (segment, offset (3,) [m] in the segment frame).
    """

    model: Any
    height_m: float
    mass_kg: float
    sex: Sex
    segment_scales: Mapping[str, float]
    joints: tuple[JointSpec, ...]
    segment_joint: Mapping[str, int]
    dof_names: tuple[str, ...]
    markers: Mapping[str, tuple[str, FloatArray]] = field(default_factory=dict)
    bare_model: Any = None  # the same model without marker frames

    # -- sizes and names -------------------------------------------------------------------
    @property
    def nq(self) -> int:
        return int(self.model.nq)

    @property
    def nv(self) -> int:
        return int(self.model.nv)

    @property
    def segments(self) -> tuple[str, ...]:
        return tuple(self.segment_joint)

    @property
    def marker_names(self) -> tuple[str, ...]:
        return tuple(self.markers)

    @property
    def rotational_dofs(self) -> np.ndarray:
        """(nv,) bool: velocity components that are angles (all but the root translation)."""
        mask = np.ones(self.nv, dtype=bool)
        mask[:3] = False
        return mask

    def neutral(self) -> FloatArray:
        """Standing neutral configuration (nq,): pelvis at hip height, all angles zero."""
        import pinocchio as pin

        q = np.asarray(pin.neutral(self.model), dtype=float).copy()
        q[2] = self.hip_height()
        return q

    def hip_height(self) -> float:
        """Height of the hip joint centres above the sole in the neutral pose [m]."""
        thigh = self.segment_length("thigh_r")
        shank = self.segment_length("shank_r")
        return thigh + shank + 0.039 * self.height_m * self.segment_scales.get("foot_r", 1.0)

    def segment_length(self, segment: str) -> float:
        """Distance from the segment's origin to its first child joint's centre [m] (thigh:
        hip to knee, shank: knee to ankle, pelvis: mid-hip to lumbar joint)."""
        for j in self.joints:
            if j.parent == segment:
                return float(np.linalg.norm(j.position)) * self.segment_scales.get(segment, 1.0)
        raise ConfigError(f"segment {segment!r} has no child joint; segments: {self.segments}")

    def dof_index(self, name: str) -> int:
        """Velocity index (in ``v``) of a revolute DOF; ``q`` index is this + 1."""
        try:
            return 6 + self.dof_names.index(name)
        except ValueError:
            raise ConfigError(
                f"DOF {name!r} not in the model; DOFs: {', '.join(self.dof_names)}"
            ) from None

    def dof_limits(self) -> tuple[FloatArray, FloatArray]:
        """(42,) lower and upper limits [rad] of the revolute DOFs."""
        lo = np.asarray(self.model.lowerPositionLimit[7:], dtype=float).copy()
        hi = np.asarray(self.model.upperPositionLimit[7:], dtype=float).copy()
        return lo, hi

    def descendants(self, segment: str) -> set[str]:
        """Segments at or below ``segment`` in the tree."""
        out = {segment}
        changed = True
        while changed:
            changed = False
            for j in self.joints:
                if j.parent in out and j.child not in out:
                    out.add(j.child)
                    changed = True
        return out

    def segment_depth(self) -> dict[str, int]:
        """Segment -> number of anatomical joints between it and the pelvis."""
        depth = {"pelvis": 0}
        for j in self.joints:  # parents come first
            depth[j.child] = depth[j.parent] + 1
        return depth

    def dof_segment(self) -> dict[str, str]:
        """Revolute DOF name -> the child segment its joint moves."""
        return {d.name: j.child for j in self.joints for d in j.dofs}

    # -- markers ---------------------------------------------------------------------------
    def with_markers(self, markers: Mapping[str, tuple[str, Any]]) -> HumanModel:
        """A copy whose marker frames ``marker:NAME`` are exactly ``markers`` (segment,
        offset [m]); markers attached before are replaced."""
        import pinocchio as pin

        model = pin.Model(self.bare_model if self.bare_model is not None else self.model)
        placed: dict[str, tuple[str, FloatArray]] = {}
        for name, (segment, offset) in markers.items():
            if segment not in self.segment_joint:
                raise ConfigError(
                    f"marker {name!r}: segment {segment!r} is not in the model; segments: "
                    f"{', '.join(self.segments)}"
                )
            off = np.asarray(offset, dtype=float).reshape(3)
            jid = self.segment_joint[segment]
            parent_frame = model.getFrameId(segment)
            model.addFrame(
                pin.Frame(
                    f"marker:{name}",
                    jid,
                    parent_frame,
                    pin.SE3(np.eye(3), off),
                    pin.FrameType.OP_FRAME,
                )
            )
            placed[name] = (segment, off)
        return HumanModel(
            model,
            self.height_m,
            self.mass_kg,
            self.sex,
            dict(self.segment_scales),
            self.joints,
            dict(self.segment_joint),
            self.dof_names,
            placed,
            self.bare_model if self.bare_model is not None else self.model,
        )


def build_human_model(
    height_m: float = 1.75,
    mass_kg: float = 75.0,
    sex: Sex = "male",
    segment_scales: Mapping[str, float] | None = None,
) -> HumanModel:
    """Build the skeleton for a subject.

    Args:
        height_m: stature [m]; lengths scale with it (de Leva).
        mass_kg: body mass [kg]; segment masses are de Leva's fractions of it.
        sex: which de Leva table.
        segment_scales: optional per-segment length factors (e.g. from static scaling);
            a segment's factor scales the positions of its child joints, its centre of mass
            and its radii of gyration (moments by the square).

    Returns:
        The :class:`HumanModel` (no markers attached).
    """
    import pinocchio as pin

    joints = _joints(height_m, sex)
    inertias = _inertias(height_m, mass_kg, sex)
    scales = {seg: 1.0 for seg in inertias}
    for seg, value in (segment_scales or {}).items():
        if seg not in scales:
            raise ConfigError(
                f"segment_scales: unknown segment {seg!r}; segments: {', '.join(scales)}"
            )
        if not (np.isfinite(value) and 0.3 <= value <= 3.0):
            raise ConfigError(
                f"segment_scales[{seg!r}] = {value}: expected a factor between 0.3 and 3 "
                "(a larger factor usually means the marker units are wrong)"
            )
        scales[seg] = float(value)

    model = pin.Model()
    model.name = "mocapkit_human"
    segment_joint: dict[str, int] = {}

    def add_segment(segment: str, jid: int) -> None:
        inert = inertias[segment]
        s = scales[segment]
        inertia = pin.Inertia(
            inert.mass, np.asarray(inert.com) * s, np.diag(np.asarray(inert.moments) * s * s)
        )
        model.appendBodyToJoint(jid, inertia, pin.SE3.Identity())
        frame_parent = model.addJointFrame(jid)
        model.addFrame(
            pin.Frame(segment, jid, frame_parent, pin.SE3.Identity(), pin.FrameType.BODY)
        )
        segment_joint[segment] = jid

    root = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "root")
    add_segment("pelvis", root)
    dof_names: list[str] = []
    lower: list[float] = []
    upper: list[float] = []
    for spec in joints:
        parent_jid = segment_joint[spec.parent]
        placement = pin.SE3(np.eye(3), np.asarray(spec.position) * scales[spec.parent])
        jid = parent_jid
        for i, dof in enumerate(spec.dofs):
            axis = np.asarray(dof.axis, dtype=float)
            axis /= np.linalg.norm(axis)
            jid = model.addJoint(
                jid,
                pin.JointModelRevoluteUnaligned(axis),
                placement if i == 0 else pin.SE3.Identity(),
                dof.name,
            )
            if i < len(spec.dofs) - 1:
                model.addJointFrame(jid)
            dof_names.append(dof.name)
            lower.append(dof.lower_deg * _DEG)
            upper.append(dof.upper_deg * _DEG)
        add_segment(spec.child, jid)
    lo = np.asarray(model.lowerPositionLimit, dtype=float).copy()
    hi = np.asarray(model.upperPositionLimit, dtype=float).copy()
    lo[:7], hi[:7] = -np.inf, np.inf
    lo[3:7], hi[3:7] = -1.01, 1.01
    lo[7:], hi[7:] = lower, upper
    model.lowerPositionLimit = lo
    model.upperPositionLimit = hi
    return HumanModel(
        model,
        height_m,
        mass_kg,
        sex,
        scales,
        tuple(joints),
        segment_joint,
        tuple(dof_names),
        {},
        model,
    )


def anatomical_joint_names(human: HumanModel) -> tuple[str, ...]:
    """The 25 anatomical joints (root first)."""
    return ("root", *(j.name for j in human.joints))
