"""Human motion for retargeting: world poses of the human segments over time, from either
half of mocapkit, plus the same segments in the subject's neutral standing pose.

- marker trials (C3D/TRC): reconstructed by mocapkit, then the scaled model's forward
  kinematics (:func:`from_reconstruction`);
- joint angles on OpenSim's coordinate names (a mocapkit ``.mot``, an inertial recording
  through the body model): the ``full_body_15`` sensor tree's skeleton places the segments
  (:func:`from_coordinates`; root translation from ``pelvis_t?`` when given).

World: z up, metres, ground at z = 0 (the lowest foot point of the trial when the source
has no ground).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import DataError
from mocapkit.geometry import quat_from_matrix

# sensor-tree segment -> human model segment (the names the robot YAML uses)
TREE_TO_HUMAN = {
    "pelvis": "pelvis", "torso": "thorax", "head": "head",
    "humerus_r": "upper_arm_r", "radius_r": "forearm_r", "hand_r": "hand_r",
    "humerus_l": "upper_arm_l", "radius_l": "forearm_l", "hand_l": "hand_l",
    "femur_r": "thigh_r", "tibia_r": "shank_r", "calcn_r": "foot_r",
    "femur_l": "thigh_l", "tibia_l": "shank_l", "calcn_l": "foot_l",
}  # fmt: skip


@dataclass(frozen=True)
class HumanMotion:
    """``pos[seg]`` (N, 3) [m] and ``quat[seg]`` (N, 4) ``q_world_segment`` over ``time``
    (N,); ``neutral_pos`` / ``neutral_quat``: the same segments standing, arms down,
    facing +x, feet on z = 0. ``foot_height``: (N,) per foot segment, its lowest point."""

    time: FloatArray
    pos: dict[str, FloatArray]
    quat: dict[str, FloatArray]
    neutral_pos: dict[str, FloatArray]
    neutral_quat: dict[str, FloatArray]
    source: str = ""

    @property
    def n_frames(self) -> int:
        return int(self.time.size)

    @property
    def segments(self) -> tuple[str, ...]:
        return tuple(self.pos)


def from_reconstruction(rec: object, segments: tuple[str, ...]) -> HumanMotion:
    """From :func:`mocapkit.reconstruct`'s result: forward kinematics of the scaled model."""
    result = rec.result  # type: ignore[attr-defined]
    return model_motion(rec.subject.human, result.time, result.q, segments)  # type: ignore[attr-defined]


def model_motion(
    human: Any, time: FloatArray, q: FloatArray, segments: tuple[str, ...], *,
    ground: float | None = None,
) -> HumanMotion:  # fmt: skip
    """The scaled human model's segments over time (forward kinematics of ``q`` (N, nq));
    ``ground``: as :func:`from_coordinates` (a piece of a longer reconstruction)."""
    import pinocchio as pin

    model = human.bare_model if human.bare_model is not None else human.model
    data = model.createData()
    missing = [s for s in segments if not model.existFrame(s)]
    if missing:
        raise DataError(f"the human model has no segment(s) {', '.join(missing)}")
    ids = {s: model.getFrameId(s) for s in segments}
    q_all = np.asarray(q, dtype=float)
    n = q_all.shape[0]
    pos = {s: np.empty((n, 3)) for s in segments}
    rot = {s: np.empty((n, 3, 3)) for s in segments}
    for k in range(n):
        pin.framesForwardKinematics(model, data, q_all[k, : model.nq])
        for s, f in ids.items():
            pos[s][k] = data.oMf[f].translation
            rot[s][k] = data.oMf[f].rotation
    q0 = human.neutral()
    pin.framesForwardKinematics(model, data, q0[: model.nq])
    n_pos = {s: np.array(data.oMf[f].translation) for s, f in ids.items()}
    n_rot = {s: np.array(data.oMf[f].rotation) for s, f in ids.items()}
    return _on_the_ground(
        np.asarray(time, dtype=float),
        pos,
        {s: quat_from_matrix(r) for s, r in rot.items()},
        n_pos,
        {s: quat_from_matrix(r) for s, r in n_rot.items()},
        "markers",
        ground,
    )


ANKLE_HEIGHT_M = 0.04  # the foot segments' origin (ankle) above the sole


def _on_the_ground(
    time: FloatArray,
    pos: Mapping[str, FloatArray],
    quat: dict[str, FloatArray],
    n_pos: Mapping[str, FloatArray],
    n_quat: dict[str, FloatArray],
    source: str,
    ground: float | None = None,
) -> HumanMotion:
    """The motion with its ground at z = 0 (``ground``, or :func:`ground_height` of this
    motion's feet) and its neutral pose standing on z = 0."""
    if ground is None:
        ground = ground_height([p for s, p in pos.items() if s.startswith("foot")])
    return HumanMotion(
        time=time,
        pos={s: p - [0.0, 0.0, ground] for s, p in pos.items()},
        quat=quat,
        neutral_pos=_standing(n_pos),
        neutral_quat=n_quat,
        source=source,
    )


def ground_height(feet: list[FloatArray]) -> float:
    """The ground under feet (N, 3) each: a low percentile (2 %) of their heights, less the
    ankle's height above the sole (0 without feet)."""
    if not feet:
        return 0.0
    heights = np.concatenate([p[:, 2] for p in feet])
    return float(np.nanpercentile(heights, 2.0)) - ANKLE_HEIGHT_M


def _standing(n_pos: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
    """The neutral pose's segment positions with its soles on z = 0."""
    soles = [p[2] for s, p in n_pos.items() if s.startswith(("foot", "toes"))]
    sole = (min(soles) - ANKLE_HEIGHT_M) if soles else -ANKLE_HEIGHT_M
    return {s: p - [0.0, 0.0, sole] for s, p in n_pos.items()}


@lru_cache(maxsize=1)
def _skeleton() -> tuple[object, dict[str, object]]:
    """The ``full_body_15`` tree and its segments standing at all-zero coordinates."""
    from mocapkit.body.sensor_tree import SensorTree
    from mocapkit.body.simulate import segment_poses

    tree = SensorTree.preset("full_body_15")
    zero = {c: np.zeros(1) for c in tree.coordinate_names}
    return tree, dict(segment_poses(tree, np.zeros(1), zero, speed=0.0))


def from_coordinates(
    time: FloatArray, coords: Mapping[str, FloatArray], segments: tuple[str, ...], *,
    ground: float | None = None, first_height: float | None = None,
) -> HumanMotion:  # fmt: skip
    """From joint angles on OpenSim's coordinate names (rad; ``pelvis_t?`` in m, OpenSim's
    y-up ground) through the ``full_body_15`` skeleton. A piece of a longer recording
    gives the same frames as the whole does with the whole's ``ground`` (its
    :func:`ground_height`, on the segments as ``ground=0.0`` places them) and
    ``first_height`` (``pelvis_ty`` of its first frame)."""
    pos, quat, n_pos, n_quat = _coordinate_poses(time, coords, segments, first_height)
    return _on_the_ground(np.asarray(time, dtype=float), pos, quat, n_pos, n_quat,
                          "joint angles", ground)  # fmt: skip


def _coordinate_poses(
    time: FloatArray, coords: Mapping[str, FloatArray], segments: tuple[str, ...],
    first_height: float | None,
) -> tuple[dict[str, FloatArray], dict[str, FloatArray], dict[str, FloatArray],
           dict[str, FloatArray]]:  # fmt: skip
    """Segment positions and orientations over time, and standing (:func:`from_coordinates`),
    before the ground is placed."""
    from mocapkit.body.simulate import segment_poses

    tree_obj, neutral = _skeleton()
    tree: Any = tree_obj
    n = time.size
    use = {c: np.nan_to_num(np.asarray(coords[c], dtype=float)) for c in tree.coordinate_names
           if c in coords}  # fmt: skip
    missing_root = [c for c in ("pelvis_tilt", "pelvis_list", "pelvis_rotation") if c not in use]
    if missing_root:
        raise DataError(f"joint angles: no {', '.join(missing_root)}; the pelvis is needed")
    full = {c: use.get(c, np.zeros(n)) for c in tree.coordinate_names}
    poses = segment_poses(tree, time, full, speed=0.0)
    # OpenSim ground (x fwd, y up, z right) -> ours (x fwd, y left, z up)
    trans = np.zeros((n, 3))
    if all(c in coords for c in ("pelvis_tx", "pelvis_ty", "pelvis_tz")):
        tx, ty, tz = (np.asarray(coords[c], dtype=float) for c in ("pelvis_tx", "pelvis_ty",
                                                                   "pelvis_tz"))  # fmt: skip
        trans = np.column_stack([tx, -tz, ty])
        # the tree's own pelvis height stands for the first frame's
        trans[:, 2] -= trans[0, 2] if first_height is None else first_height
    pos, quat, n_pos, n_quat = {}, {}, {}, {}
    inverse = {v: k for k, v in TREE_TO_HUMAN.items()}
    for s in segments:
        if s not in inverse:
            raise DataError(
                f"joint angles drive the segments {', '.join(TREE_TO_HUMAN.values())}; the "
                f"robot map also names {s!r}"
            )
        p = poses[inverse[s]]
        pos[s] = p.pos + trans
        quat[s] = p.quat
        n_pos[s] = neutral[inverse[s]].pos[0]  # type: ignore[attr-defined]
        n_quat[s] = neutral[inverse[s]].quat[0]  # type: ignore[attr-defined]
    return pos, quat, n_pos, n_quat


class FrameSkeleton:
    """:func:`from_coordinates` one frame at a time, for the live path: the skeleton's
    forward kinematics in one numba call (``body._kernels.pose_frame_kernel``, tens of
    microseconds instead of milliseconds of numpy on one-row arrays). Same motion as
    ``from_coordinates`` on that frame alone (tests/retarget/test_live.py)."""

    def __init__(self, segments: tuple[str, ...]) -> None:
        from mocapkit.body.calibration import q_world_ground
        from mocapkit.body.joint_angles import joint_tables

        tree_obj, neutral = _skeleton()
        tree: Any = tree_obj
        inverse = {v: k for k, v in TREE_TO_HUMAN.items()}
        unknown = [s for s in segments if s not in inverse]
        if unknown:
            raise DataError(
                f"joint angles drive the segments {', '.join(TREE_TO_HUMAN.values())}; the "
                f"robot map also names {unknown[0]!r}"
            )
        self.coordinate_names: tuple[str, ...] = tuple(tree.coordinate_names)
        index = {c: k for k, c in enumerate(self.coordinate_names)}
        self._q_b, self._signs, self._offsets = joint_tables(tree)
        slots = np.full((len(tree.segments), 3), -1, dtype=np.int64)
        for i, seg in enumerate(tree.segments):
            order = seg.joint.slots()[0]
            for j in range(3):
                c = seg.joint.coordinates[order[j]]
                slots[i, j] = index[c] if c is not None else -1
        self._slots = slots
        self._parents = np.ascontiguousarray(tree.parent_index, dtype=np.int64)
        self._seg_offset = np.array([np.asarray(s.offset, dtype=float) for s in tree.segments])
        self._q_wg = np.ascontiguousarray(q_world_ground(0.0))
        names = [s.name for s in tree.segments]
        self.segments = segments
        self._rows = [names.index(inverse[s]) for s in segments]
        self._feet = [k for k, s in enumerate(segments) if s.startswith("foot")]
        n_pos = {s: neutral[inverse[s]].pos[0] for s in segments}  # type: ignore[attr-defined]
        self._neutral_pos = _standing(n_pos)
        self._neutral_quat = {s: neutral[inverse[s]].quat[0] for s in segments}  # type: ignore[attr-defined]
        n = len(tree.segments)
        self._values = np.zeros(len(self.coordinate_names))
        self._q = np.empty((n, 4))
        self._p = np.empty((n, 3))
        self._work = np.empty((n, 7))

    def __call__(self, t: float, coords: Mapping[str, float]) -> HumanMotion:
        """One frame of joint angles [rad] (``pelvis_t?`` [m] optional) -> its motion."""
        from mocapkit.body._kernels import pose_frame_kernel

        for c in ("pelvis_tilt", "pelvis_list", "pelvis_rotation"):
            if c not in coords:
                raise DataError(f"joint angles: no {c}; the pelvis is needed")
        v = self._values
        for k, c in enumerate(self.coordinate_names):
            x = float(coords.get(c, 0.0))
            v[k] = x if x == x and abs(x) != np.inf else 0.0  # as np.nan_to_num for angles
        pose_frame_kernel(v, self._slots, self._signs, self._offsets, self._q_b, self._parents,
                          self._seg_offset, self._q_wg, self._q, self._p, self._work)  # fmt: skip
        shift = np.zeros(3)
        if all(c in coords for c in ("pelvis_tx", "pelvis_ty", "pelvis_tz")):
            shift[:2] = float(coords["pelvis_tx"]), -float(coords["pelvis_tz"])
        feet = sorted(self._p[self._rows[k], 2] + shift[2] for k in self._feet)
        ground = 0.0
        if feet:  # np.nanpercentile(feet, 2) (linear), less the ankle's height
            at = 0.02 * (len(feet) - 1)
            lo = int(at)
            hi = min(lo + 1, len(feet) - 1)
            ground = feet[lo] + (at - lo) * (feet[hi] - feet[lo]) - ANKLE_HEIGHT_M
        shift[2] -= ground
        pos = {
            s: (self._p[r] + shift)[None] for s, r in zip(self.segments, self._rows, strict=True)
        }
        quat = {s: self._q[r].copy()[None] for s, r in zip(self.segments, self._rows, strict=True)}
        return HumanMotion(np.array([t], dtype=float), pos, quat, self._neutral_pos,
                           self._neutral_quat, "joint angles")  # fmt: skip


# BVH joint names (lower case, any "prefix:" dropped) -> human segments
BVH_NAMES = {
    "pelvis": ("hips", "hip", "pelvis", "root"),
    "thorax": ("spine2", "chest", "spine1", "torso", "thorax", "upperchest"),
    "head": ("head",),
    "upper_arm_r": ("rightarm", "rightupperarm", "r_upperarm", "humerus_r", "rshldr"),
    "forearm_r": ("rightforearm", "rightlowerarm", "r_forearm", "radius_r", "rforearm"),
    "hand_r": ("righthand", "r_hand", "hand_r", "rhand"),
    "upper_arm_l": ("leftarm", "leftupperarm", "l_upperarm", "humerus_l", "lshldr"),
    "forearm_l": ("leftforearm", "leftlowerarm", "l_forearm", "radius_l", "lforearm"),
    "hand_l": ("lefthand", "l_hand", "hand_l", "lhand"),
    "thigh_r": ("rightupleg", "rightupperleg", "r_thigh", "femur_r", "rthigh"),
    "shank_r": ("rightleg", "rightlowerleg", "r_shin", "tibia_r", "rshin"),
    "foot_r": ("rightfoot", "r_foot", "calcn_r", "rfoot"),
    "thigh_l": ("leftupleg", "leftupperleg", "l_thigh", "femur_l", "lthigh"),
    "shank_l": ("leftleg", "leftlowerleg", "l_shin", "tibia_l", "lshin"),
    "foot_l": ("leftfoot", "l_foot", "calcn_l", "lfoot"),
}
_UNITS = ((1.0, "m"), (0.01, "cm"), (0.0254, "in"), (0.001, "mm"))


def from_bvh(path: str | object, segments: tuple[str, ...]) -> tuple[HumanMotion, list[str]]:
    """From a BVH file (y up, as BVH has it; the unit told from the leg length, with a
    note): joint names mapped to human segments (:data:`BVH_NAMES`), forward kinematics,
    the rest pose as the neutral one (arms turned down first when the rest is a T-pose)."""
    from mocapkit.body.skeleton import local_rotations
    from mocapkit.geometry import quat_mul, quat_rotate
    from mocapkit.io.bvh import read_bvh

    motion = read_bvh(path)  # type: ignore[arg-type]
    joints = motion.joints
    key = {j.name.split(":")[-1].lower(): i for i, j in enumerate(joints)}
    index: dict[str, int] = {}
    for seg in segments:
        hit = next((key[n] for n in BVH_NAMES.get(seg, ()) if n in key), None)
        if hit is None:
            raise DataError(
                f"{path}: no BVH joint for the human segment {seg!r} (looked for "
                f"{', '.join(BVH_NAMES.get(seg, ()))}); its joints: "
                f"{', '.join(j.name for j in joints)}"
            )
        index[seg] = hit
    local = local_rotations(motion)
    n = motion.n_frames
    up = np.array([0.70710678, 0.70710678, 0.0, 0.0])  # y up -> z up (+90 deg about x)
    q_w = np.zeros((len(joints), n, 4))
    p_w = np.zeros((len(joints), n, 3))
    q_rest = np.zeros((len(joints), 4))
    p_rest = np.zeros((len(joints), 3))
    for i, j in enumerate(joints):
        lq = local.get(j.name, np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)))
        if j.parent < 0:
            pos_ch = [c for c in j.channels if c.endswith("position")]
            p = j.offset + (motion.joint_channels(j.name)[:, [j.channels.index(c) for c in pos_ch]]
                            if len(pos_ch) == 3 else 0.0)  # fmt: skip
            p = np.broadcast_to(p, (n, 3)) if np.ndim(p) == 1 else p
            q_w[i] = quat_mul(np.broadcast_to(up, (n, 4)), lq)
            p_w[i] = quat_rotate(up, p)
            q_rest[i] = up
            p_rest[i] = quat_rotate(up, j.offset)
        else:
            q_w[i] = quat_mul(q_w[j.parent], lq)
            p_w[i] = p_w[j.parent] + quat_rotate(q_w[j.parent], np.broadcast_to(j.offset, (n, 3)))
            q_rest[i] = q_rest[j.parent]
            p_rest[i] = p_rest[j.parent] + quat_rotate(q_rest[j.parent], j.offset)
    # the unit: the one that makes the legs 0.5-1.2 m long
    legs = [s for s in ("thigh_r", "foot_r") if s in index]
    notes = []
    scale = 1.0
    if len(legs) == 2:
        leg = float(np.linalg.norm(p_rest[index["thigh_r"]] - p_rest[index["foot_r"]]))
        for s, unit in _UNITS:
            if 0.5 <= leg * s <= 1.2:
                scale = s
                notes.append(f"{path}: BVH lengths read as {unit} (leg {leg * s:.2f} m)")
                break
        else:
            notes.append(f"{path}: leg length {leg:.3g} in file units fits no unit; taken as m")
    pos = {s: p_w[i] * scale for s, i in index.items()}
    quat = {s: q_w[i] for s, i in index.items()}
    n_pos = {s: p_rest[i] * scale for s, i in index.items()}
    n_quat = {s: q_rest[i].copy() for s, i in index.items()}
    _arms_down(n_pos, n_quat, notes)
    t = np.arange(n, dtype=np.float64) * float(motion.frame_time)
    return _on_the_ground(t, pos, quat, n_pos, n_quat, "BVH"), notes


def _arms_down(pos: dict[str, FloatArray], quat: dict[str, FloatArray], notes: list[str]) -> None:
    """A rest pose with the arms out (T-pose) is turned arms-down (the neutral the robots'
    reference postures share), about each shoulder."""
    from mocapkit.geometry import quat_from_two_vectors, quat_mul, quat_rotate

    for side in ("r", "l"):
        arm = [f"upper_arm_{side}", f"forearm_{side}", f"hand_{side}"]
        if not all(a in pos for a in arm[:2]):
            continue
        d = pos[arm[1]] - pos[arm[0]]
        down = np.array([0.0, 0.0, -1.0])
        if float(d @ down) / max(float(np.linalg.norm(d)), 1e-9) > np.cos(np.radians(30.0)):
            continue
        fix = quat_from_two_vectors(d, down)
        origin = pos[arm[0]].copy()
        for a in arm:
            if a in pos:
                pos[a] = origin + quat_rotate(fix, pos[a] - origin)
                quat[a] = quat_mul(fix, quat[a])
        notes.append(f"the BVH rest pose holds the {'right' if side == 'r' else 'left'} arm out: "
                     "turned down for the neutral pose")  # fmt: skip
