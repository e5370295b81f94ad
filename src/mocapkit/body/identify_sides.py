"""Left and right: telling mirror-image branches apart (step 3 of
:mod:`mocapkit.body.identify`).

The two legs (and the two arms) cost the same to the topology. Two kinds of evidence
decide, and must agree when both are there:

- **joint centres** (needs accelerometers): in the parent sensor's frame, down is along
  the limbs, forward is where the knees do not bend to (or where the elbows do), right is
  forward x up; the hip (shoulder) joint centre of the right limb lies on the right. No
  world heading is used, so 6D orientations work.
- **gait** (used alone only without joint centres; a clear joint-centre side
  outweighs it): while walking the pelvis turns to bring the swinging leg's hip forward
  (``pelvis_rotation`` in phase with ``hip_flexion_r - hip_flexion_l``) and each arm swings
  against the leg of its side (joint angles from the body model, automatic calibration).

Without either (no accelerometers and no walking), or when they disagree, the pair is
reported as undecided with the reason.
"""

from __future__ import annotations

import itertools
import logging
import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.joint_centres import (
    Kinematics,
    PairFit,
    centre_error,
    centre_in,
    centre_swing,
    in_frame_of,
)
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import DataError
from mocapkit.series import OrientationSeries

# Gait coupling: |correlation| below this cannot tell left from right.
MIN_COUPLING = 0.25
# Joint-centre side: the share of the two joints' separation along the body's right.
MIN_SIDE_SHARE = 0.3
SURE_SIDE_SHARE = 0.9  # a joint-centre side this clear outweighs the gait
MAX_CENTRE_ERROR = 0.25  # standard error of a joint centre, share of the separation
# 6D: the side's geometry goes through the heading between the parent's and the limb's
# worlds, which only the joint centre's horizontal acceleration shows; below this RMS
# [m/s^2] (joint_centres.centre_swing) the side is not taken from the joint centres. A
# simulated pelvis gliding at constant speed: 0.16-0.30 (the side against the gait in 2
# of 10 lower-body suits, once at 0.91 of the separation, which outweighed it);
# walking: 0.56-1.43 on the real recordings, 1.15-2.7 simulated with the pelvis bouncing
# and swaying. Set on those runs: no held-out set.
MIN_CENTRE_SWING = 0.4


def _canon(tree: SensorTree, i: int, children: list[list[int]]) -> str:
    return "(" + "".join(sorted(_canon(tree, c, children) for c in children[i])) + ")"


def mirror_pairs(tree: SensorTree) -> list[tuple[int, int]]:
    """Pairs of sibling segments whose subtrees have the same shape (their labels can be
    swapped, with their whole branches, at no cost to the topology)."""
    parent = tree.parent_index
    children: list[list[int]] = [[] for _ in parent]
    for i, p in enumerate(parent):
        if p >= 0:
            children[p].append(i)
    out = []
    for kids in children:
        for a, b in itertools.combinations(kids, 2):
            if _canon(tree, a, children) == _canon(tree, b, children):
                out.append((a, b))
    return out


def branch(tree: SensorTree, root: int) -> list[int]:
    parent = tree.parent_index
    out = [root]
    for i in range(len(parent)):
        if parent[i] >= 0 and parent[i] in out:
            out.append(i)
    return out


def swap_branches(tree: SensorTree, perm: np.ndarray, a: int, b: int) -> np.ndarray:
    """perm with the branches under a and b exchanged (same shapes, segment order kept)."""
    out = perm.copy()
    ba, bb = branch(tree, a), branch(tree, b)
    out[ba], out[bb] = perm[bb], perm[ba]
    return out


def _side(name: str) -> str | None:
    if name.endswith("_r"):
        return "r"
    if name.endswith("_l"):
        return "l"
    return None


def _zscore(x: FloatArray) -> FloatArray:
    x = x - np.nanmean(x)
    sd = float(np.nanstd(x))
    return x / sd if sd > 1e-9 else x * 0.0


def _corr(a: FloatArray, b: FloatArray) -> float:
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 10:
        return 0.0
    return float(np.mean(_zscore(a[ok]) * _zscore(b[ok])))


def gait_couplings(angles: Any) -> dict[str, float]:
    """Correlations that tell left from right while walking (module docstring): ``legs``
    (pelvis rotation against hip flexion r - l; positive when the legs are labelled right)
    and ``arms`` (arm flexion r - l against hip flexion r - l; negative when right)."""
    names = set(angles.names)
    out: dict[str, float] = {}
    if {"hip_flexion_r", "hip_flexion_l"} <= names:
        hip = angles.column("hip_flexion_r") - angles.column("hip_flexion_l")
        if "pelvis_rotation" in names:
            out["legs"] = _corr(np.unwrap(angles.column("pelvis_rotation")), hip)
        if {"arm_flex_r", "arm_flex_l"} <= names:
            out["arms"] = -_corr(angles.column("arm_flex_r") - angles.column("arm_flex_l"), hip)
    return out


def same_mirror(tree: SensorTree, k: int, other: int, pairs: list[tuple[int, int]]) -> bool:
    for a, b in pairs:
        ba, bb = set(branch(tree, a)), set(branch(tree, b))
        if (k in ba and other in bb) or (k in bb and other in ba):
            return True
    return False


def decide_sides(
    tree: SensorTree,
    names: list[str],
    perm: np.ndarray,
    orientations: Mapping[str, OrientationSeries],
    headings: str,
    pinned: Mapping[int, int],
    fits: dict[tuple[int, int], PairFit] | None,
    kin: Kinematics | None,
) -> tuple[np.ndarray, dict[int, tuple[float, str]], list[str]]:
    """Mirror-image branches: by the joint centres' side, by gait, by a pin, or undecided."""
    pairs = mirror_pairs(tree)
    side_conf: dict[int, tuple[float, str]] = {}
    undecided: list[str] = []
    if not pairs:
        return perm, side_conf, undecided
    segs = list(tree.segment_names)
    res = _labelled_body(tree, names, perm, orientations, headings)
    for a, b in pairs:
        members = set(branch(tree, a)) | set(branch(tree, b))
        label = f"{segs[a]} / {segs[b]}"
        if members & set(pinned):
            for k in members:
                side_conf[k] = (1.0, f"{label} decided by the pinned sensor")
            continue
        coords = [c or "" for c in tree.segments[a].joint.coordinates]
        kind = "legs" if any(c.startswith("hip_") for c in coords) else "arms"
        evidence: list[tuple[float, str]] = []  # (signed score: + keeps, - swaps; text)
        geo = _centre_side(tree, perm, a, b, kin, fits, headings)
        if geo is not None and abs(geo) >= MIN_SIDE_SHARE:
            evidence.append((geo, f"joint centres ({abs(geo):.2f} of the separation across "
                             "the body)"))  # fmt: skip
        c = gait_couplings(res.body.angles).get(kind) if res is not None else None
        if c is not None and abs(c) >= MIN_COUPLING:
            sign = 1.0 if _side(segs[a]) != "l" else -1.0
            evidence.append((sign * c, f"gait ({kind} coupling r={abs(c):.2f})"))
        signs = {e[0] > 0 for e in evidence}
        if len(signs) > 1 and abs(evidence[0][0]) >= SURE_SIDE_SHARE:
            # the joint centres need no calibration; the gait's angles do (in 6D a
            # calibration can turn an arm round): a clear joint-centre side wins
            evidence = [(evidence[0][0], f"{evidence[0][1]}, against the gait")]
            signs = {evidence[0][0] > 0}
        if not evidence or len(signs) > 1:
            if len(signs) > 1:
                why = f"{label}: the joint centres and the gait disagree on left and right"
            else:
                why = (
                    f"{label}: left and right cannot be told apart: "
                    + ("no accelerometer samples for the joint centres" if fits is None
                       else "the joint centres do not show the side")
                    + (f", and the {kind} show no gait coupling (r={c:+.2f}, needs |r| >= "
                       f"{MIN_COUPLING})" if c is not None else ", and no gait to compare by")
                )  # fmt: skip
            why += f". Walk 10-20 s with arm swing, or pin one side (--known {segs[a]}=SENSOR)"
            undecided.append(why)
            for k in members:
                side_conf[k] = (0.5, why)
            continue
        score = max(abs(e[0]) for e in evidence) * (1.0 if evidence[0][0] > 0 else -1.0)
        if score < 0:
            perm = swap_branches(tree, perm, a, b)
            res = _labelled_body(tree, names, perm, orientations, headings)
        conf = float(min(1.0, 0.5 + abs(score)))
        text = " and ".join(e[1] for e in evidence)
        for k in members:
            side_conf[k] = (conf, f"left/right by {text}")
    return perm, side_conf, undecided


def _labelled_body(
    tree: SensorTree,
    names: list[str],
    perm: np.ndarray,
    orientations: Mapping[str, OrientationSeries],
    headings: str,
) -> Any:
    """The body model (automatic calibration) under labelling ``perm``, or None."""
    from mocapkit.body.pipeline import run_body

    labelled = tree.with_sensor_names(
        {seg.name: names[int(perm[k])] for k, seg in enumerate(tree.segments)}
    )
    quiet = logging.getLogger("mocapkit.body.joint_angles")  # gimbal notes: not ours here
    was = quiet.disabled
    quiet.disabled = True
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return run_body(
                labelled,
                orientations,
                calibration="auto",
                heading_alignment="pose" if headings == "independent" else "shared",
            )
    except DataError:
        return None
    finally:
        quiet.disabled = was


def _centre_side(
    tree: SensorTree,
    perm: np.ndarray,
    a: int,
    b: int,
    kin: Kinematics | None,
    fits: dict[tuple[int, int], PairFit] | None,
    headings: str = "shared",
) -> float | None:
    """Which side of the parent segment a's joint lies on, from the joint centres alone
    (no world heading, so 6D works): in the parent sensor's frame, down is along the limbs
    (parent joint -> next joint), forward is where the knees do not bend to (or where the
    elbows do), and right is forward x up. Returns the share of a's offset from b along
    the right (+: a is on its named side; -: swap), or None without three-segment limbs,
    or, with independent headings, when the joints' centres hardly accelerate
    sideways (:data:`MIN_CENTRE_SWING`)."""
    if fits is None or kin is None:
        return None
    p = int(tree.parent_index[a])
    if headings == "independent" and any(
        centre_swing(kin, fits, int(perm[p]), int(perm[k])) < MIN_CENTRE_SWING for k in (a, b)
    ):
        return None
    fwd_p, up_p = [], []
    for seg in (a, b):
        limb = _limb(tree, seg)
        if limb is None:
            return None
        mid, end, sign = limb
        i_p, i_s, i_m, i_e = (int(perm[k]) for k in (p, seg, mid, end))
        axis_s = centre_in(fits, i_s, i_m) - centre_in(fits, i_s, i_p)  # proximal -> distal
        axis_m = centre_in(fits, i_m, i_e) - centre_in(fits, i_m, i_s)
        if not (np.isfinite(axis_s).all() and np.isfinite(axis_m).all()):
            return None
        n_s = axis_s / max(float(np.linalg.norm(axis_s)), 1e-9)
        bent = in_frame_of(kin, fits, i_s, i_m, axis_m)  # the next segment, in seg's frame
        dev = bent - (bent @ n_s)[:, None] * n_s
        fwd_s = sign * np.mean(dev, axis=0)
        if float(np.linalg.norm(fwd_s)) < 1e-3:
            return None
        fwd_p.append(np.mean(in_frame_of(kin, fits, i_p, i_s, fwd_s), axis=0))
        up_p.append(-np.mean(in_frame_of(kin, fits, i_p, i_s, n_s), axis=0))
    fwd, up = np.mean(fwd_p, axis=0), np.mean(up_p, axis=0)
    right = np.cross(fwd, up)
    right /= max(float(np.linalg.norm(right)), 1e-12)
    ip = int(perm[p])
    d = centre_in(fits, ip, int(perm[a])) - centre_in(fits, ip, int(perm[b]))
    sep = float(np.linalg.norm(d))
    if not (np.isfinite(sep) and 0.05 <= sep <= 0.8):
        return None
    se = max(centre_error(fits, ip, int(perm[a])), centre_error(fits, ip, int(perm[b])))
    if se > MAX_CENTRE_ERROR * sep:  # the parent hardly turned: its joint centres are unknown
        return None
    score = float(d @ right / sep)
    return -score if _side(tree.segments[a].name) == "l" else score


def _limb(tree: SensorTree, seg: int) -> tuple[int, int, int] | None:
    """(middle segment, end segment, +1 when the middle joint bends forward (elbow) or -1
    backward (knee)) for a limb of three segments starting at ``seg``."""
    parent = tree.parent_index
    kids = [k for k in range(len(parent)) if parent[k] == seg]
    if len(kids) != 1:
        return None
    mid = kids[0]
    ends = [k for k in range(len(parent)) if parent[k] == mid]
    if len(ends) != 1:
        return None
    coords = " ".join(c or "" for c in tree.segments[mid].joint.coordinates)
    if "knee" in coords:
        return mid, ends[0], -1
    if "elbow" in coords:
        return mid, ends[0], 1
    return None
