"""numba kernel of the segment retargeting (one frame), the fast path of
:class:`mocapkit.robot.segment_retarget.SegmentRetargeter`.

Readable reference: ``SegmentRetargeter._joint_angles_reference`` (numpy); the two agree
to 1e-9 (tests/robot/test_retarget.py). Same steps: each segment's rotation since the
initialisation posture applied to the robot's segment there, eq. 16 (``R_parent^T
R_child``), proper Euler (1, 2, 1) about the group's axes, the candidate closest to the
previous frame (2 pi shifts, limit excess and an unfollowable third angle penalised),
then clipping to the limits.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_TWO_PI = 2.0 * math.pi


@njit(cache=True, inline="always")
def _wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


@njit(cache=True)
def retarget_frame(
    R_h,  # (S, 3, 3) human segments in the chest frame
    R0T,  # (S, 3, 3) their transposes at the initialisation posture
    R_init,  # (S, 3, 3) the robot's segments at q_init
    g_seg,  # (G,) segment of each group
    g_parent,  # (G,) parent segment (-1: the chest)
    g_start,  # (G,) first joint index
    g_k,  # (G,) number of joints (2 or 3)
    C,  # (G, 3, 3) columns a1, a2, a1 x a2 in the parent robot frame
    R_psi,  # (G, 3, 3)
    psi,  # (G,)
    virtual,  # (G,) bool: a 2-joint group with a virtual third axis
    R_local_init_T,  # (G, 3, 3)
    q_init,  # (n,)
    lower,  # (n,)
    upper,  # (n,)
    q_prev,  # (n,) in/out: the previous frame's solution
    q_out,  # (n,) out
    clipped,  # (n,) bool out
    dropped,  # (G,) out [rad]
    targets,  # (S, 3, 3) work
    clip_tol,  # [rad] beyond a limit by more than this counts as clipped
):
    for s in range(R_h.shape[0]):
        targets[s] = R_h[s] @ R0T[s] @ R_init[s]
    q_out[:] = q_init
    d = np.empty(3)
    best = np.empty(3)
    for g in range(g_seg.shape[0]):
        R_child = targets[g_seg[g]]
        if g_parent[g] < 0:
            R_local = R_child.copy()
        else:
            R_local = targets[g_parent[g]].T @ R_child  # eq. 16
        Cg = C[g]
        local = Cg.T @ (R_local @ R_local_init_T[g] @ R_psi[g]) @ Cg
        sb = math.hypot(local[1, 0], local[2, 0])
        b = math.atan2(sb, local[0, 0])
        if sb < 1e-9:
            e0, e1, e2 = math.atan2(local[2, 1], local[1, 1]), b, 0.0
        else:
            e0 = math.atan2(local[1, 0], -local[2, 0])
            e1 = b
            e2 = math.atan2(local[0, 1], local[0, 2])
        k = g_k[g]
        j0 = g_start[g]
        best_cost = np.inf
        for cand in range(2):
            if cand == 0:
                d[0], d[1], d[2] = e0, e1 - psi[g], e2
            else:
                d[0], d[1], d[2] = e0 + math.pi, -e1 - psi[g], e2 + math.pi
            cost = 0.0
            for j in range(3):
                ref = d[j] if j >= k else q_prev[j0 + j] - q_init[j0 + j]
                d[j] -= _TWO_PI * np.rint((d[j] - ref) / _TWO_PI)
                if j < k:
                    lo = lower[j0 + j] - q_init[j0 + j]
                    hi = upper[j0 + j] - q_init[j0 + j]
                    ex = max(lo - d[j], 0.0) + max(d[j] - hi, 0.0)
                    cost += (d[j] - ref) ** 2 + 100.0 * ex * ex
            if virtual[g]:
                w = _wrap(d[2])
                cost += 1e3 * w * w
            if cost < best_cost:
                best_cost = cost
                best[0], best[1], best[2] = d[0], d[1], d[2]
        for j in range(k):
            q_out[j0 + j] = q_init[j0 + j] + best[j]
        dropped[g] = _wrap(best[2]) if virtual[g] else 0.0
    for i in range(q_out.shape[0]):
        clipped[i] = q_out[i] < lower[i] - clip_tol or q_out[i] > upper[i] + clip_tol
        q_out[i] = min(max(q_out[i], lower[i]), upper[i])
        q_prev[i] = q_out[i]
