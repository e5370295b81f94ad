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
    import pinocchio as pin

    human = rec.subject.human  # type: ignore[attr-defined]
    result = rec.result  # type: ignore[attr-defined]
    model = human.bare_model if human.bare_model is not None else human.model
    data = model.createData()
    missing = [s for s in segments if not model.existFrame(s)]
    if missing:
        raise DataError(f"the human model has no segment(s) {', '.join(missing)}")
    ids = {s: model.getFrameId(s) for s in segments}
    q_all = np.asarray(result.q, dtype=float)
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
    ground = _ground_height(pos)
    sole0 = (
        min(n_pos[s][2] for s in n_pos if s.startswith(("foot", "toes")))
        if any(s.startswith(("foot", "toes")) for s in n_pos)
        else 0.0
    )
    return HumanMotion(
        time=np.asarray(result.time, dtype=float),
        pos={s: p - [0.0, 0.0, ground] for s, p in pos.items()},
        quat={s: quat_from_matrix(r) for s, r in rot.items()},
        neutral_pos={s: p - [0.0, 0.0, sole0 - 0.04] for s, p in n_pos.items()},
        neutral_quat={s: quat_from_matrix(r) for s, r in n_rot.items()},
        source="markers",
    )


def _ground_height(pos: Mapping[str, FloatArray]) -> float:
    """The ground under the feet: a low percentile of the foot segments' heights, less the
    ankle's height above the sole (4 cm)."""
    feet = [p[:, 2] for s, p in pos.items() if s.startswith("foot")]
    if not feet:
        return 0.0
    return float(np.nanpercentile(np.concatenate(feet), 2.0)) - 0.04


def from_coordinates(
    time: FloatArray, coords: Mapping[str, FloatArray], segments: tuple[str, ...]
) -> HumanMotion:
    """From joint angles on OpenSim's coordinate names (rad; ``pelvis_t?`` in m, OpenSim's
    y-up ground) through the ``full_body_15`` skeleton."""
    from mocapkit.body.sensor_tree import SensorTree
    from mocapkit.body.simulate import segment_poses

    tree = SensorTree.preset("full_body_15")
    n = time.size
    use = {c: np.nan_to_num(np.asarray(coords[c], dtype=float)) for c in tree.coordinate_names
           if c in coords}  # fmt: skip
    missing_root = [c for c in ("pelvis_tilt", "pelvis_list", "pelvis_rotation") if c not in use]
    if missing_root:
        raise DataError(f"joint angles: no {', '.join(missing_root)}; the pelvis is needed")
    full = {c: use.get(c, np.zeros(n)) for c in tree.coordinate_names}
    poses = segment_poses(tree, time, full, speed=0.0)
    zero = {c: np.zeros(1) for c in tree.coordinate_names}
    neutral = segment_poses(tree, np.zeros(1), zero, speed=0.0)
    # OpenSim ground (x fwd, y up, z right) -> ours (x fwd, y left, z up)
    trans = np.zeros((n, 3))
    if all(c in coords for c in ("pelvis_tx", "pelvis_ty", "pelvis_tz")):
        tx, ty, tz = (np.asarray(coords[c], dtype=float) for c in ("pelvis_tx", "pelvis_ty",
                                                                   "pelvis_tz"))  # fmt: skip
        trans = np.column_stack([tx, -tz, ty])
        trans[:, 2] -= trans[0, 2]  # the tree's own pelvis height stands for the first frame
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
        n_pos[s] = neutral[inverse[s]].pos[0]
        n_quat[s] = neutral[inverse[s]].quat[0]
    sole = min((v[2] for k, v in n_pos.items() if k.startswith("foot")), default=0.0)
    ground = _ground_height(pos)
    return HumanMotion(
        time=np.asarray(time, dtype=float),
        pos={s: p - [0.0, 0.0, ground] for s, p in pos.items()},
        quat=quat,
        neutral_pos={s: p - [0.0, 0.0, sole - 0.04] for s, p in n_pos.items()},
        neutral_quat=n_quat,
        source="joint angles",
    )
