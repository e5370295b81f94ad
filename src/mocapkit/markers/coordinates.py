"""Named joint coordinates from configurations, with OpenSim's names and meanings.

The project's rule (docs/architecture.md): human coordinates use OpenSim's names and
senses, those of the Rajagopal (2015) model that the body (IMU) side reports, so IMU and
marker results compare directly with each other and with OpenSim. Columns:

- ``pelvis_tx, pelvis_ty, pelvis_tz`` [m] and ``pelvis_tilt, pelvis_list, pelvis_rotation``
  [rad] in OpenSim's ground frame (y up: ``v_os = (x, z, -y)`` of our z-up world) with
  OpenSim's intrinsic Z-X-Y sequence;
- model DOFs whose meaning is OpenSim's, by name: ``hip_*``, ``knee_angle_*``,
  ``ankle_angle_*``, ``subtalar_angle_*``, ``mtp_angle_*``, ``elbow_flex_*``, ``pro_sup_*``,
  ``wrist_flex_*``, ``wrist_dev_*``;
- OpenSim coordinates of joints that our model splits into several (:data:`DERIVED`),
  computed from the two segments' relative orientation with OpenSim's axes and rotation
  order: ``lumbar_*`` (thorax on pelvis: Rajagopal's ``back``, over our abdomen and thorax
  joints), ``neck_*`` (head on thorax: the body side's ``neck``, over our cervical and head
  joints), ``arm_flex_s, arm_add_s, arm_rot_s`` (upper arm on thorax: Rajagopal's
  ``acromial``, over our sternoclavicular and shoulder joints);
- the shoulder girdle, which OpenSim's models lack: ``sc_elevation_s, sc_protraction_s``
  (clavicle on thorax; its rotation is included in ``arm_*``).

The model's own DOFs behind derived coordinates (``abdomen_*``, ``thorax_*``,
``cervical_*``, ``head_extension``, ``shoulder_*``) stay in ``q``; their names differ from
OpenSim's on purpose (docs/markers.md has the table).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.human_model import HumanModel
from mocapkit.errors import ConfigError
from mocapkit.geometry import (
    euler_from_quat,
    quat_conj,
    quat_from_axis_angle,
    quat_from_matrix,
    quat_from_xyzw,
    quat_mul,
    quat_to_matrix,
)

PELVIS_COLUMNS = (
    "pelvis_tx",
    "pelvis_ty",
    "pelvis_tz",
    "pelvis_tilt",
    "pelvis_list",
    "pelvis_rotation",
)
# our z-up world (x fwd, y left, z up) -> OpenSim ground (x fwd, y up, z right)
Z_UP_TO_OPENSIM = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
# Middle angles closer than this to +-90 deg make the outer two ill-defined (gimbal lock).
NEAR_GIMBAL_DEG = 10.0


@dataclass(frozen=True)
class DerivedJoint:
    """Three OpenSim coordinates of the rotation of ``child`` relative to ``parent``, about
    the axes of the model DOFs ``axes_from`` (in the parent frame at the neutral pose,
    intrinsic order), computed over every model DOF between the two segments."""

    names: tuple[str, str, str]
    parent: str
    child: str
    axes_from: tuple[str, str, str]


def _derived(side_names: tuple[str, ...]) -> tuple[DerivedJoint, ...]:
    out = [
        DerivedJoint(
            ("lumbar_extension", "lumbar_bending", "lumbar_rotation"),
            "pelvis",
            "thorax",
            ("abdomen_extension", "abdomen_bending", "abdomen_rotation"),
        ),
        DerivedJoint(
            ("neck_extension", "neck_bending", "neck_rotation"),
            "thorax",
            "head",
            ("cervical_extension", "cervical_bending", "cervical_rotation"),
        ),
    ]
    for s in side_names:
        out.append(
            DerivedJoint(
                (f"arm_flex_{s}", f"arm_add_{s}", f"arm_rot_{s}"),
                "thorax",
                f"upper_arm_{s}",
                (f"shoulder_flexion_{s}", f"shoulder_adduction_{s}", f"shoulder_rotation_{s}"),
            )
        )
    return tuple(out)


DERIVED = _derived(("r", "l"))


@dataclass(frozen=True)
class _Chain:
    """A derived joint resolved on a model: DOF indices (into ``q[7:]``) from parent to
    child with their axes, the decomposition frame, and per coordinate the signed DOFs
    whose sum approximates it (to pick the Euler solution and the 2 pi branch)."""

    joint: DerivedJoint
    dofs: tuple[int, ...]
    axes: FloatArray  # (len(dofs), 3)
    q_frame: FloatArray  # (4,) decomposition frame F = [a1, a2, a1 x a2] in the parent
    third_sign: float
    hint: FloatArray  # (3, len(dofs)) signs (0 where a DOF does not contribute)


@dataclass(frozen=True)
class CoordinateMap:
    """How the reported coordinates come from a model's ``q`` (see the module docstring).

    Attributes:
        names: reported coordinate names (pelvis columns first).
        source: per name, ``("dof", i)`` (``q[7 + i]``) or ``("derived", c, k)`` (coordinate
            k of chain c), or ``("pelvis", k)``.
        depends: per name, the model DOF indices (into ``q[7:]``) it depends on (pelvis
            columns: none; they need the root).
        chains: the resolved derived joints.
    """

    names: tuple[str, ...]
    source: tuple[tuple[str, int, int], ...]
    depends: tuple[tuple[int, ...], ...]
    chains: tuple[_Chain, ...]

    @property
    def angular(self) -> np.ndarray:
        mask = np.ones(len(self.names), dtype=bool)
        mask[:3] = False
        return mask


def _chain_dofs(human: HumanModel, parent: str, child: str) -> list[str]:
    """Model DOFs from ``parent`` down to ``child`` (in kinematic order)."""
    by_child = {j.child: j for j in human.joints}
    dofs: list[str] = []
    seg = child
    while seg != parent:
        if seg not in by_child:
            raise ConfigError(f"segment {child!r} is not below {parent!r} in the model")
        j = by_child[seg]
        dofs = [d.name for d in j.dofs] + dofs
        seg = j.parent
    return dofs


def coordinate_map(human: HumanModel) -> CoordinateMap:
    """The reported coordinates of ``human`` (every derived joint whose DOFs exist)."""
    axis_of = {d.name: np.asarray(d.axis, float) / np.linalg.norm(d.axis) for j in human.joints
               for d in j.dofs}  # fmt: skip
    index = {n: i for i, n in enumerate(human.dof_names)}
    chains: list[_Chain] = []
    covered: dict[int, int] = {}  # dof index -> chain that reports it
    for joint in DERIVED:
        if not all(a in index for a in joint.axes_from):
            continue
        names = _chain_dofs(human, joint.parent, joint.child)
        axes = np.array([axis_of[n] for n in names])
        a1, a2, a3 = (axis_of[n] for n in joint.axes_from)
        F = np.column_stack([a1, a2, np.cross(a1, a2)])
        hint = np.zeros((3, len(names)))
        for k, a in enumerate((a1, a2, a3)):
            dots = axes @ a
            hint[k] = np.where(np.abs(dots) > 0.99, np.sign(dots), 0.0)
        c = len(chains)
        chains.append(
            _Chain(
                joint,
                tuple(index[n] for n in names),
                axes,
                quat_from_matrix(F),
                float(np.sign(a3 @ np.cross(a1, a2))),
                hint,
            )
        )
        for n in names:
            covered[index[n]] = c
    names_out: list[str] = list(PELVIS_COLUMNS)
    source: list[tuple[str, int, int]] = [("pelvis", k, 0) for k in range(6)]
    depends: list[tuple[int, ...]] = [()] * 6
    emitted: set[int] = set()
    for i, dof in enumerate(human.dof_names):
        ch = covered.get(i)
        if ch is None:
            names_out.append(dof)
            source.append(("dof", i, 0))
            depends.append((i,))
            continue
        if dof.startswith("sc_"):  # the girdle: reported under its own names as well
            names_out.append(dof)
            source.append(("dof", i, 0))
            depends.append((i,))
        if ch not in emitted and not dof.startswith("sc_"):
            emitted.add(ch)
            for k, name in enumerate(chains[ch].joint.names):
                names_out.append(name)
                source.append(("derived", ch, k))
                depends.append(chains[ch].dofs)
    return CoordinateMap(tuple(names_out), tuple(source), tuple(depends), tuple(chains))


def coordinate_names(human: HumanModel) -> tuple[str, ...]:
    return coordinate_map(human).names


def _wrap(a: FloatArray) -> FloatArray:
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


def derived_angles(chain: _Chain, dof_values: FloatArray) -> tuple[FloatArray, np.ndarray]:
    """(N, 3) coordinates [rad] of one derived joint from its DOF values (N, len(dofs)),
    and (N,) near-gimbal flags (middle angle within NEAR_GIMBAL_DEG of +-90 deg).

    The relative rotation is the product of the chain's axis-angle rotations (joint
    placements carry no rotation), expressed in F and decomposed intrinsic XYZ. Of the two
    Euler solutions and their 2 pi shifts, the one nearest the summed DOFs along each axis
    is kept, so the coordinates follow the model continuously; in exact gimbal lock the
    third keeps that estimate and the first takes the rest."""
    n = dof_values.shape[0]
    q = np.tile(np.array([1.0, 0.0, 0.0, 0.0]), (n, 1))
    for k in range(len(chain.dofs)):
        q = quat_mul(q, quat_from_axis_angle(chain.axes[k], dof_values[:, k]))
    qf = chain.q_frame
    q_joint = quat_mul(quat_mul(quat_conj(qf)[None], q), qf[None])
    a, gimbal = euler_from_quat(q_joint, "XYZ", return_gimbal=True)
    a[:, 2] *= chain.third_sign
    hint = dof_values @ chain.hint.T  # (N, 3)
    s3 = chain.third_sign
    alt = np.column_stack([a[:, 0] + np.pi, np.pi - a[:, 1], a[:, 2] + np.pi])
    if gimbal.any():
        # only a1 + s a3 is defined (s: sign of the middle angle); keep a3 = its estimate
        s = np.where(a[:, 1] > 0.0, 1.0, -1.0) * s3
        total = a[:, 0] + s * a[:, 2]
        a[gimbal, 2] = hint[gimbal, 2]
        a[gimbal, 0] = total[gimbal] - s[gimbal] * hint[gimbal, 2]
        alt[gimbal] = a[gimbal]
    near = hint + _wrap(a - hint)
    near_alt = hint + _wrap(alt - hint)
    use_alt = ((near_alt - hint) ** 2).sum(axis=1) < ((near - hint) ** 2).sum(axis=1)
    out = np.where(use_alt[:, None], near_alt, near)
    close = np.abs(np.abs(out[:, 1]) - 0.5 * np.pi) < np.radians(NEAR_GIMBAL_DEG)
    return out, close


def coordinates_from_q(
    human: HumanModel, Q: FloatArray, cmap: CoordinateMap | None = None
) -> FloatArray:
    """(N, len(names)) coordinates [m, rad] from configurations (N, nq)."""
    return coordinates_and_gimbal(human, Q, cmap)[0]


def coordinates_and_gimbal(
    human: HumanModel, Q: FloatArray, cmap: CoordinateMap | None = None
) -> tuple[FloatArray, dict[str, np.ndarray]]:
    """Coordinates (N, K) and, per derived joint (named by its middle coordinate), the
    (N,) flags of frames near gimbal lock."""
    cm = cmap or coordinate_map(human)
    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    C = Z_UP_TO_OPENSIM
    R = quat_to_matrix(quat_from_xyzw(Q[:, 3:7]))  # (N, 3, 3) world <- pelvis, ours
    R_os = C @ R @ C.T
    pelvis = np.empty((Q.shape[0], 6))
    pelvis[:, :3] = Q[:, :3] @ C.T
    pelvis[:, 3:] = euler_from_quat(quat_from_matrix(R_os), "ZXY")
    angles = Q[:, 7:]
    derived: list[FloatArray] = []
    gimbal: dict[str, np.ndarray] = {}
    for ch in cm.chains:
        vals, close = derived_angles(ch, angles[:, list(ch.dofs)])
        derived.append(vals)
        gimbal[ch.joint.names[1]] = close
    out = np.empty((Q.shape[0], len(cm.names)))
    for col, (kind, a, b) in enumerate(cm.source):
        if kind == "pelvis":
            out[:, col] = pelvis[:, a]
        elif kind == "dof":
            out[:, col] = angles[:, a]
        else:
            out[:, col] = derived[a][:, b]
    return out, gimbal


def angular_columns(human: HumanModel) -> np.ndarray:
    """(len(names),) bool: columns that are angles (degrees at the edges)."""
    return coordinate_map(human).angular


# -- coordinate tasks given with OpenSim names -----------------------------------------------
def resolve_coordinate_tasks(
    human: HumanModel, tasks: Mapping[str, tuple[float, float]], where: str = "coordinate tasks"
) -> tuple[dict[str, tuple[float, float]], list[str]]:
    """Coordinate tasks (name -> (value [rad], weight)) on model DOFs.

    A model DOF is taken as is. An OpenSim coordinate that the model computes from several
    DOFs (``lumbar_*``, ``neck_*``, ``arm_*``) is spread over the DOFs about its axis: the
    value is shared equally between the spine's (or neck's) joints, and ``arm_*`` holds the
    shoulder DOF with the girdle free (exact when the other angles of the joint are zero;
    each such mapping is returned as a note). Names that are neither raise
    :class:`ConfigError` (``pelvis_*``: the root is free in this model).
    """
    cm = coordinate_map(human)
    out: dict[str, tuple[float, float]] = {}
    notes: list[str] = []
    for name, (value, weight) in tasks.items():
        if name in human.dof_names:
            out[name] = (float(value), float(weight))
            continue
        for ch in cm.chains:
            if name not in ch.joint.names:
                continue
            k = ch.joint.names.index(name)
            members = [
                (human.dof_names[ch.dofs[i]], float(ch.hint[k, i]))
                for i in range(len(ch.dofs))
                if ch.hint[k, i] != 0.0
            ]
            if ch.joint.names[0].startswith("arm_"):
                members = [(n, s) for n, s in members if n.startswith("shoulder_")]
            for dof, sign in members:
                out[dof] = (sign * float(value) / len(members), float(weight))
            notes.append(
                f"{where}: {name} = {np.degrees(value):.1f} deg held as "
                + " + ".join(f"{d}" for d, _ in members)
                + (" (shared equally)" if len(members) > 1 else "")
            )
            break
        else:
            raise ConfigError(
                f"{where}: {name!r} is not a coordinate of this model; coordinates: "
                f"{', '.join(cm.names[6:])} (or a model DOF: {', '.join(human.dof_names)})"
            )
    return out, notes


# -- other OpenSim models' conventions -------------------------------------------------------
# Coordinates whose sense differs from Rajagopal's (ours) in other OpenSim models, by sign.
# gait2392 (the OpenSim gait tutorial's model) turns the knee the other way: flexion < 0.
MODEL_SIGNS: dict[str, dict[str, float]] = {
    "rajagopal": {},
    "gait2392": {"knee_angle_r": -1.0, "knee_angle_l": -1.0},
}
_KNEE_FLEXED_BACK_DEG = -2.0  # a median knee angle below this is gait2392's sign


def detect_model_convention(labels: Sequence[str], values_deg: FloatArray) -> str:
    """``"gait2392"`` when the knee columns of a table (N, K) [deg] are mostly negative (a
    knee flexed backwards on the median is anatomically impossible: gait2392's sign),
    else ``"rajagopal"``."""
    knees = [i for i, c in enumerate(labels) if c in ("knee_angle_r", "knee_angle_l")]
    if not knees:
        return "rajagopal"
    vals = np.asarray(values_deg, dtype=float)[:, knees]
    vals = vals[np.isfinite(vals)]
    if vals.size and float(np.median(vals)) < _KNEE_FLEXED_BACK_DEG:
        return "gait2392"
    return "rajagopal"


def to_rajagopal(
    labels: Sequence[str], values: FloatArray, model: str = "auto"
) -> tuple[FloatArray, str]:
    """A table (N, K) of another OpenSim model's coordinates in our (Rajagopal's) senses;
    ``model``: ``"auto"`` (:func:`detect_model_convention`), ``"gait2392"`` or
    ``"rajagopal"``. Returns the converted copy and the convention used."""
    vals = np.array(values, dtype=float, copy=True)
    used = detect_model_convention(labels, vals) if model == "auto" else model
    if used not in MODEL_SIGNS:
        raise ConfigError(
            f"reference model {model!r}: expected auto or one of {', '.join(MODEL_SIGNS)}"
        )
    for i, c in enumerate(labels):
        vals[:, i] *= MODEL_SIGNS[used].get(c, 1.0)
    return vals, used


# -- derivatives -------------------------------------------------------------------------------
_NEAR_ZERO_COS = 1e-12  # |cos(middle angle)| floor: exact gimbal lock gives a huge, finite rate


def _axis_angle_matrices(axis: FloatArray, angle: FloatArray) -> FloatArray:
    """(N, 3, 3) rotations about the unit ``axis`` (3,) by ``angle`` (N,) [rad]."""
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = axis
    C = 1.0 - c
    return np.stack(
        [
            np.stack([c + x * x * C, x * y * C - z * s, x * z * C + y * s], axis=-1),
            np.stack([y * x * C + z * s, c + y * y * C, y * z * C - x * s], axis=-1),
            np.stack([z * x * C - y * s, z * y * C + x * s, c + z * z * C], axis=-1),
        ],
        axis=-2,
    )


def _safe_cos(b: FloatArray) -> FloatArray:
    cb = np.cos(b)
    return np.where(np.abs(cb) < _NEAR_ZERO_COS, np.where(cb < 0, -1.0, 1.0) * _NEAR_ZERO_COS, cb)


def _xyz_rates(a: FloatArray, b: FloatArray, w: FloatArray) -> FloatArray:
    """Rates (N, 3, k) of intrinsic X-Y-Z angles (first ``a``, middle ``b``: (N,)) for the
    spatial angular velocities ``w`` (N, 3, k): ω = ȧ e_x + ḃ R_x e_y + ċ R_x R_y e_z."""
    ca, sa = np.cos(a)[:, None], np.sin(a)[:, None]
    cb, sb = _safe_cos(b)[:, None], np.sin(b)[:, None]
    wx, wy, wz = w[:, 0], w[:, 1], w[:, 2]
    c_dot = (wz * ca - wy * sa) / cb
    return np.stack([wx - c_dot * sb, wy * ca + wz * sa, c_dot], axis=1)


def _zxy_rates(a: FloatArray, b: FloatArray, w: FloatArray) -> FloatArray:
    """Rates (N, 3, k) of intrinsic Z-X-Y angles: ω = ȧ e_z + ḃ R_z e_x + ċ R_z R_x e_y."""
    ca, sa = np.cos(a)[:, None], np.sin(a)[:, None]
    cb, sb = _safe_cos(b)[:, None], np.sin(b)[:, None]
    wx, wy, wz = w[:, 0], w[:, 1], w[:, 2]
    c_dot = (wy * ca - wx * sa) / cb
    return np.stack([wz - c_dot * sb, wx * ca + wy * sa, c_dot], axis=1)


def coordinate_jacobian(
    human: HumanModel,
    Q: FloatArray,
    cmap: CoordinateMap | None = None,
    coords: FloatArray | None = None,
) -> FloatArray:
    """(N, K, nv) derivative of the reported coordinates with respect to the model's
    velocity coordinates (the free-flyer's local twist, then the joints), analytically:

    - ``pelvis_t*`` = C p: ∂/∂v_lin = C R (C: z-up world to OpenSim ground, R: pelvis);
    - pelvis angles, intrinsic Z-X-Y of C R Cᵀ: their rates for the spatial angular
      velocity C R ω_local;
    - a model DOF's own column: 1;
    - a derived joint: spatial angular velocity of the child in the parent,
      Σ_k (R_1 ⋯ R_{k-1}) a_k θ̇_k, in the chain's frame F, through the intrinsic X-Y-Z
      rates (the third scaled by its sign). The second Euler solution (a + π, π − b, c + π)
      gives the same rates with the middle one negated, which the formula yields by itself
      from the reported angles.

    ``coords`` (N, K): the coordinates of Q when already computed. At exact gimbal lock the
    rates are huge (|cos b| floored at 1e-12), as the finite differences would be.
    """
    cm = cmap or coordinate_map(human)
    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    C = coords if coords is not None else coordinates_from_q(human, Q, cm)
    n, nv, K = Q.shape[0], human.nv, len(cm.names)
    G = np.zeros((n, K, nv))
    R = quat_to_matrix(quat_from_xyzw(Q[:, 3:7]))  # (N, 3, 3) world <- pelvis
    CR = Z_UP_TO_OPENSIM @ R  # (N, 3, 3): v_lin and ω_local -> OpenSim ground
    G[:, 0:3, 0:3] = CR
    G[:, 3:6, 3:6] = _zxy_rates(C[:, 3], C[:, 4], CR)
    for col, (kind, a, _b) in enumerate(cm.source):
        if kind == "dof":
            G[:, col, 6 + a] = 1.0
    for c, ch in enumerate(cm.chains):
        cols = [col for col, (kind, a, _) in enumerate(cm.source) if kind == "derived" and a == c]
        order = [cm.source[col][2] for col in cols]
        if len(cols) != 3 or order != [0, 1, 2]:
            raise ConfigError(f"derived joint {ch.joint.names}: columns out of order")
        F = quat_to_matrix(ch.q_frame)
        cum = np.tile(np.eye(3), (n, 1, 1))
        w = np.empty((n, 3, len(ch.dofs)))
        for k, dof in enumerate(ch.dofs):
            w[:, :, k] = cum @ ch.axes[k]
            cum = cum @ _axis_angle_matrices(ch.axes[k], Q[:, 7 + dof])
        rates = _xyz_rates(C[:, cols[0]], C[:, cols[1]], np.einsum("ji,njk->nik", F, w))
        rates[:, 2] *= ch.third_sign
        G[:, cols[0] : cols[0] + 3, [6 + d for d in ch.dofs]] = rates
    return G
