"""numba kernels of the body kinematics: one frame (streaming) and a batch loop over frames.

Readable reference: :mod:`mocapkit.body.joint_angles` (numpy through mocapkit.geometry).
The two agree to 1e-9 (tests/body/test_kinematics.py). The Euler decomposition here is
the intrinsic-XYZ case of the direct method of Bernardes and Viollet (2022) used by
:func:`mocapkit.geometry.euler_from_quat`, specialised so it needs no allocation.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from mocapkit.geometry.euler import GIMBAL_TOLERANCE
from mocapkit.geometry.kernels import conj_mul_into, quat_mul_into

_PI = math.pi


@njit(cache=True, inline="always")
def _wrap(a: float) -> float:
    return _PI - np.mod(_PI - a, 2.0 * _PI)


@njit(cache=True)
def euler_xyz_intrinsic(q, out):
    """Intrinsic XYZ angles of unit q into out (3,); returns True in gimbal lock
    (then the third angle is 0, as in mocapkit.geometry.euler_from_quat)."""
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    w, qx, qy, qz = q[0] / n, q[1] / n, q[2] / n, q[3] / n
    # extrinsic zyx: i = z, j = y, k = x, odd permutation (parity -1)
    qi, qj, qk = qz, qy, -qx
    a = w - qj
    b = qi + qk
    c = qj + w
    d = qk - qi
    middle = 2.0 * math.atan2(math.hypot(c, d), math.hypot(a, b))
    half_sum = math.atan2(b, a)
    half_diff = math.atan2(d, c)
    at_zero = abs(middle) <= GIMBAL_TOLERANCE
    at_pi = abs(middle - _PI) <= GIMBAL_TOLERANCE
    if at_zero:
        first_e, third_e = 0.0, 2.0 * half_sum
    elif at_pi:
        first_e, third_e = 0.0, 2.0 * half_diff
    else:
        first_e, third_e = half_sum - half_diff, half_sum + half_diff
    out[0] = _wrap(-third_e)
    out[1] = middle - 0.5 * _PI
    out[2] = _wrap(first_e)
    return at_zero or at_pi


@njit(cache=True)
def frame_kernel(
    q_in, t, mount, heading, q_b, parents, q_wg, signs, offsets, seg_idx, ang_idx,
    hold, max_hold, near_limit,
    last_q, last_t, cont, have_prev, last_third,
    q_seg, out, stale, gimbal, near, work,
):  # fmt: skip
    """One frame. Inputs q_in (S, 4) (NaN rows: missing); state arrays are updated in place:
    last_q (S, 4), last_t (S,), cont (S, 3) continuous raw angles, have_prev (S,),
    last_third (S,). Outputs: q_seg (S, 4), out (K,), stale (S,), gimbal (S,), near (S,)."""
    n_seg = q_in.shape[0]
    qs = work[0]
    tmp = work[1]
    rel = work[2]
    ang = work[3]
    for i in range(n_seg):
        ok = True
        for c in range(4):
            if not math.isfinite(q_in[i, c]):
                ok = False
        if ok:
            for c in range(4):
                last_q[i, c] = q_in[i, c]
                qs[c] = q_in[i, c]
            last_t[i] = t
            stale[i] = False
        else:
            stale[i] = True
            if hold and math.isfinite(last_t[i]) and t - last_t[i] <= max_hold + 1e-12:
                for c in range(4):
                    qs[c] = last_q[i, c]
                ok = True
        if ok:
            quat_mul_into(heading[i], qs, tmp)
            quat_mul_into(tmp, mount[i], rel)
            for c in range(4):
                q_seg[i, c] = rel[c]
        else:
            for c in range(4):
                q_seg[i, c] = np.nan
    for i in range(n_seg):
        gimbal[i] = False
        near[i] = False
        p = parents[i]
        if p < 0:
            conj_mul_into(q_wg, q_seg[i], rel)
        else:
            conj_mul_into(q_seg[p], q_seg[i], rel)
        conj_mul_into(q_b[i], rel, tmp)
        quat_mul_into(tmp, q_b[i], rel)
        if not (math.isfinite(rel[0]) and math.isfinite(rel[1])
                and math.isfinite(rel[2]) and math.isfinite(rel[3])):  # fmt: skip
            ang[0] = np.nan
            continue
        g = euler_xyz_intrinsic(rel, ang)
        if g:
            s = 1.0 if ang[1] > 0.0 else -1.0
            ang[0] = _wrap(ang[0] - s * last_third[i])
            ang[2] = last_third[i]
            gimbal[i] = True
        else:
            last_third[i] = ang[2]
        near[i] = abs(ang[1]) > near_limit
        for k in range(3):
            if have_prev[i]:
                cont[i, k] = cont[i, k] + _wrap(ang[k] - cont[i, k])
            else:
                cont[i, k] = ang[k]
        have_prev[i] = True
    for m in range(seg_idx.shape[0]):
        i = seg_idx[m]
        k = ang_idx[m]
        p = parents[i]
        valid = math.isfinite(q_seg[i, 0]) and (p < 0 or math.isfinite(q_seg[p, 0]))
        if valid:
            out[m] = signs[i, k] * cont[i, k] + offsets[i, k]
        else:
            out[m] = np.nan


@njit(cache=True)
def batch_kernel(
    q_in, time, mount, heading, q_b, parents, q_wg, signs, offsets, seg_idx, ang_idx,
    hold, max_hold, near_limit,
    last_q, last_t, cont, have_prev, last_third,
    q_seg, out, stale, gimbal, near,
):  # fmt: skip
    """frame_kernel over every frame: q_in (N, S, 4) -> q_seg (N, S, 4), out (N, K),
    stale, gimbal and near (N, S); the state arrays carry over (split runs)."""
    work = np.empty((4, 4))
    for n in range(q_in.shape[0]):
        frame_kernel(
            q_in[n], time[n], mount, heading, q_b, parents, q_wg, signs, offsets,
            seg_idx, ang_idx, hold, max_hold, near_limit,
            last_q, last_t, cont, have_prev, last_third,
            q_seg[n], out[n], stale[n], gimbal[n], near[n], work,
        )  # fmt: skip


@njit(cache=True, inline="always")
def _rotate_add(q, v, base, out):
    """``out = base + q v q*`` (3-vectors): ``v + w t + u x t``, ``u = q_xyz``, ``t = 2 u x v``."""
    w, ux, uy, uz = q[0], q[1], q[2], q[3]
    tx = 2.0 * (uy * v[2] - uz * v[1])
    ty = 2.0 * (uz * v[0] - ux * v[2])
    tz = 2.0 * (ux * v[1] - uy * v[0])
    out[0] = base[0] + v[0] + w * tx + (uy * tz - uz * ty)
    out[1] = base[1] + v[1] + w * ty + (uz * tx - ux * tz)
    out[2] = base[2] + v[2] + w * tz + (ux * ty - uy * tx)


@njit(cache=True)
def pose_frame_kernel(
    values, slot_coord, signs, offsets, q_b, parents, seg_offset, q_wg, out_q, out_p, work
):
    """One frame of coordinates -> world poses of every segment (the inverse of
    :func:`frame_kernel`; :func:`mocapkit.body.simulate.segment_poses` for one frame, the
    root at its offset). ``values`` (K,) [rad]; ``slot_coord`` (S, 3): the coordinate of
    each XYZ slot (-1: none, a zero angle); ``seg_offset`` (S, 3): each segment's origin
    in its parent [m]; out_q (S, 4) ``q_world_segment``, out_p (S, 3) [m]; ``work``
    (S, 7) scratch (the ground-frame poses). Parents come before their children."""
    qj = np.empty(4)
    tmp = np.empty(4)
    conj_b = np.empty(4)
    zero = np.zeros(3)
    for i in range(parents.shape[0]):
        a0 = (
            (values[slot_coord[i, 0]] - offsets[i, 0]) / signs[i, 0]
            if slot_coord[i, 0] >= 0
            else 0.0
        )
        a1 = (
            (values[slot_coord[i, 1]] - offsets[i, 1]) / signs[i, 1]
            if slot_coord[i, 1] >= 0
            else 0.0
        )
        a2 = (
            (values[slot_coord[i, 2]] - offsets[i, 2]) / signs[i, 2]
            if slot_coord[i, 2] >= 0
            else 0.0
        )
        # intrinsic XYZ: qx(a0) qy(a1) qz(a2)
        cx, sx = math.cos(0.5 * a0), math.sin(0.5 * a0)
        cy, sy = math.cos(0.5 * a1), math.sin(0.5 * a1)
        cz, sz = math.cos(0.5 * a2), math.sin(0.5 * a2)
        qj[0] = cx * cy * cz - sx * sy * sz
        qj[1] = sx * cy * cz + cx * sy * sz
        qj[2] = cx * sy * cz - sx * cy * sz
        qj[3] = cx * cy * sz + sx * sy * cz
        quat_mul_into(q_b[i], qj, tmp)
        conj_b[0], conj_b[1], conj_b[2], conj_b[3] = q_b[i, 0], -q_b[i, 1], -q_b[i, 2], -q_b[i, 3]
        p = parents[i]
        q_g = work[i, :4]
        p_g = work[i, 4:]
        if p < 0:
            quat_mul_into(tmp, conj_b, q_g)
            p_g[:] = seg_offset[i]
        else:
            quat_mul_into(tmp, conj_b, qj)  # q_parent_segment
            quat_mul_into(work[p, :4], qj, q_g)
            _rotate_add(work[p, :4], seg_offset[i], work[p, 4:], p_g)
    for i in range(parents.shape[0]):
        quat_mul_into(q_wg, work[i, :4], out_q[i])
        _rotate_add(q_wg, work[i, 4:], zero, out_p[i])
