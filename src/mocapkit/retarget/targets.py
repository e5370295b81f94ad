"""Human segments -> robot frame targets: heading and start aligned, every bone scaled to
the robot's, feet contacts detected from the human motion.

- **Start and heading.** The human's pelvis at the first frame is put where the robot's
  stands, facing +x (the robot's reference faces +x too), so any starting heading and
  position works.
- **Robot proportions.** Each keypoint hangs from its nearest keypoint ancestor (hand
  from forearm from upper arm from thorax from pelvis) by the robot's own bone (their
  offset in the robot's reference posture), turned as the human segment that carries it
  turned away from its neutral pose: a human pose drawn with the robot's bones. The
  pelvis moves by the pelvis-height ratio, so steps match the robot's legs.
- **Orientation.** The human segment's rotation away from its neutral pose, applied to
  the robot frame's reference orientation.
- **Feet on the ground.** Feet are placed from the ground up (their height above the
  ground in the robot's proportion, their horizontal position scaled like the pelvis), so
  a foot on the ground stays on the ground whatever the leg proportions.
- **Treadmill.** When the feet on the ground all glide backwards at one speed (above
  0.3 m/s), the trial was on a treadmill: the belt's motion is added to everything (the
  walk becomes an overground walk) and a warning says so.
- **Contacts.** A foot is in contact while it is within 3 cm of its lowest height and
  slower than 0.25 m/s (human, unscaled), for at least 0.1 s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.geometry import quat_to_matrix
from mocapkit.retarget.human import HumanMotion
from mocapkit.retarget.robot_model import Humanoid
from mocapkit.retarget.robot_spec import HUMAN_PARENT

CONTACT_HEIGHT_M = 0.03
CONTACT_SPEED_MS = 0.25
CONTACT_MIN_S = 0.1
TREADMILL_MIN_MS = 0.3


class RetargetWarning(UserWarning):
    """The retargeted motion may not be what the user expects (the message says why)."""


def belt_velocity(motion: HumanMotion, feet: list[str]) -> FloatArray:
    """(2,) the horizontal velocity of the feet while they are low (a treadmill's belt),
    zero when they do not glide together (overground)."""
    vel = []
    for f in feet:
        p = motion.pos[f]
        if p.shape[0] < 5:
            continue
        v = np.gradient(p[:, :2], motion.time, axis=0)
        low = p[:, 2] <= np.nanpercentile(p[:, 2], 5.0) + CONTACT_HEIGHT_M
        vel.append(v[low])
    if not vel:
        return np.zeros(2)
    v = np.concatenate(vel)
    med = np.median(v, axis=0)
    spread = np.median(np.linalg.norm(v - med, axis=1))
    if np.linalg.norm(med) < TREADMILL_MIN_MS or spread > 0.5 * np.linalg.norm(med):
        return np.zeros(2)
    return med


def treadmill_note(belt: FloatArray) -> str:
    """What a user is told when the belt's motion is added back."""
    return (
        f"the feet glide backwards at {np.linalg.norm(belt):.2f} m/s while on the ground: "
        "a treadmill trial. The belt's motion is added back, so the robot walks "
        "overground at that speed"
    )


def on_belt(motion: HumanMotion, belt: FloatArray, t0: float) -> HumanMotion:
    """``motion`` with a treadmill belt's travel since ``t0`` added back."""
    shift = np.zeros((motion.n_frames, 3))
    shift[:, :2] = -np.outer(motion.time - t0, belt)
    return HumanMotion(
        motion.time, {s: p + shift for s, p in motion.pos.items()}, motion.quat,
        motion.neutral_pos, motion.neutral_quat, motion.source,
    )  # fmt: skip


@dataclass(frozen=True)
class Targets:
    time: FloatArray
    pos: dict[str, FloatArray]  # keypoint segment -> (N, 3)
    rot: dict[str, FloatArray]  # keypoint segment -> (N, 3, 3)
    contact: dict[str, np.ndarray]  # foot segment -> (N,) bool
    scale: dict[str, float]  # keypoint segment -> bone scale
    belt: FloatArray  # (2,) treadmill belt velocity removed [m/s] (zero: overground)
    start: tuple[FloatArray, FloatArray] | None = None  # heading alignment and origin used


def _ancestor(segment: str, keypoints: set[str]) -> str | None:
    s = HUMAN_PARENT.get(segment)
    while s is not None and s not in keypoints:
        s = HUMAN_PARENT.get(s)
    return s


def _order(keypoints: set[str]) -> list[str]:
    def depth(s: str) -> int:
        d = 0
        while s in HUMAN_PARENT:
            s = HUMAN_PARENT[s]
            d += 1
        return d

    return sorted(keypoints, key=depth)


def yaw_matrix(rot: float) -> FloatArray:
    """(3, 3) rotation by ``rot`` [rad] about the vertical."""
    c, s = np.cos(rot), np.sin(rot)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def detect_contacts(motion: HumanMotion, foot: str) -> np.ndarray:
    """(N,) bool: the human foot is on the ground (module docstring)."""
    p = motion.pos[foot]
    n = p.shape[0]
    if n < 3:
        return np.zeros(n, dtype=bool)
    dt = np.gradient(motion.time)
    speed = np.linalg.norm(np.gradient(p[:, :2], axis=0), axis=1) / np.where(dt > 0, dt, 1.0)
    low = p[:, 2] <= np.nanpercentile(p[:, 2], 5.0) + CONTACT_HEIGHT_M
    on = low & (speed < CONTACT_SPEED_MS)
    rate = 1.0 / float(np.median(np.diff(motion.time)))
    min_len = max(1, round(CONTACT_MIN_S * rate))
    out = on.copy()
    k = 0
    while k < n:  # drop contacts shorter than min_len
        if on[k]:
            j = k
            while j < n and on[j]:
                j += 1
            if j - k < min_len:
                out[k:j] = False
            k = j
        else:
            k += 1
    return out


def make_targets(
    motion: HumanMotion,
    robot: Humanoid,
    *,
    start: tuple[FloatArray, FloatArray] | None = None,
    contact: dict[str, np.ndarray] | None = None,
    belt: tuple[FloatArray, float] | None = None,
) -> Targets:
    """Targets for every frame of ``motion`` (module docstring). ``start``: the heading
    alignment (3, 3) and origin (3,) to use instead of the first frame's (a live stream
    keeps its first frame's); ``contact``: the feet's contact flags instead of detecting
    them (a live stream detects them as it goes). The alignment used is ``Targets.start``.
    ``belt``: a treadmill belt's velocity (2,) and the time its travel counts from, to add
    back instead of finding it in ``motion`` (found only when contacts are detected here;
    a piece of a longer recording passes the whole's)."""

    spec = robot.spec
    kps = {k.segment for k in spec.keypoints}
    feet = {f.segment for f in spec.feet}
    need = kps | feet | {"pelvis"}
    missing = sorted(s for s in need if s not in motion.pos)
    if missing:
        from mocapkit.errors import DataError

        raise DataError(
            f"robot {spec.name} needs the human segment(s) {', '.join(missing)}, which this "
            f"motion ({motion.source}) does not have"
        )
    if belt is None:
        found = belt_velocity(motion, sorted(feet)) if contact is None else np.zeros(2)
        if found.any():
            import warnings

            warnings.warn(treadmill_note(found), RetargetWarning, stacklevel=2)
        belt = (found, float(motion.time[0]))
    if belt[0].any():
        motion = on_belt(motion, *belt)
    velocity = belt[0]
    frame_of = {k.segment: k.frame for k in spec.keypoints}  # (feet's sole frames apart)
    if not spec.floating_base:  # the fixed root stands for the pelvis
        frame_of["pelvis"] = str(spec.root_frame)
    ref_pos = {s: robot.ref_pose[f][0] for s, f in frame_of.items()}
    ref_rot = {s: robot.ref_pose[f][1] for s, f in frame_of.items()}

    # every segment's rotation matrices in one call (a live frame calls this 100 times a
    # second: one call per segment cost half a millisecond)
    names = sorted(need)
    r_all = quat_to_matrix(np.stack([motion.quat[s] for s in names], axis=1))  # (N, S, 3, 3)
    n_all = quat_to_matrix(np.stack([motion.neutral_quat[s] for s in names]))  # (S, 3, 3)
    n_rot = {s: n_all[i] for i, s in enumerate(names)}
    # start and heading: the human pelvis at frame 0 -> the robot's, facing +x
    r_pel_n = n_rot["pelvis"]
    fwd = r_all[0, names.index("pelvis")] @ (r_pel_n.T @ np.array([1.0, 0.0, 0.0]))
    align = yaw_matrix(-float(np.arctan2(fwd[1], fwd[0])))
    origin = motion.pos["pelvis"][0] * [1.0, 1.0, 0.0]
    if start is not None:
        align, origin = start
    pos_h = {s: (motion.pos[s] - origin) @ align.T for s in need}
    rot_h = {s: align @ r_all[:, i] for i, s in enumerate(names)}
    n_pos = {s: motion.neutral_pos[s] for s in need}
    if not spec.floating_base:
        # a fixed base cannot follow the pelvis: the human is seen from its own pelvis
        # (its pelvis held in the neutral pose), as the paper's relative control does
        to_pelvis = n_rot["pelvis"] @ np.swapaxes(rot_h["pelvis"], 1, 2)  # (N, 3, 3)
        p0 = pos_h["pelvis"]
        pos_h = {s: n_pos["pelvis"] + np.einsum("nij,nj->ni", to_pelvis, p - p0)
                 for s, p in pos_h.items()}  # fmt: skip
        rot_h = {s: to_pelvis @ r for s, r in rot_h.items()}

    s_root = float(ref_pos["pelvis"][2] / max(n_pos["pelvis"][2], 1e-6))
    scale = {"pelvis": s_root}
    pos_t: dict[str, FloatArray] = {}
    root = np.column_stack(
        [
            s_root * pos_h["pelvis"][:, 0] + ref_pos["pelvis"][0],
            s_root * pos_h["pelvis"][:, 1] + ref_pos["pelvis"][1],
            ref_pos["pelvis"][2] + s_root * (pos_h["pelvis"][:, 2] - n_pos["pelvis"][2]),
        ]
    )
    pos_t["pelvis"] = root if spec.floating_base else np.tile(ref_pos["pelvis"], (len(root), 1))
    for s in _order(kps - {"pelvis"}):
        a = _ancestor(s, kps | {"pelvis"}) or "pelvis"
        human_bone = float(np.linalg.norm(n_pos[s] - n_pos[a]))
        robot_bone = ref_pos[s] - ref_pos[a]
        scale[s] = float(np.linalg.norm(robot_bone)) / human_bone if human_bone > 1e-6 else 1.0
        # the robot's own bone, turned as the human's segment that carries it turned
        delta = rot_h[a] @ n_rot[a].T  # (N, 3, 3) world rotation away from neutral
        pos_t[s] = pos_t[a] + delta @ robot_bone
        if s in ("foot_r", "foot_l"):  # from the ground up: on the ground stays on the ground
            pos_t[s][:, 2] = ref_pos[s][2] + scale[s] * (pos_h[s][:, 2] - n_pos[s][2])
    rot_t = {}
    for s in kps:
        delta = rot_h[s] @ n_rot[s].T  # the human's rotation away from neutral (world)
        rot_t[s] = delta @ ref_rot[s]
    if contact is None:
        contact = {f: detect_contacts(motion, f) for f in feet}
    return Targets(motion.time, pos_t, rot_t, contact, scale, velocity, (align, origin))
