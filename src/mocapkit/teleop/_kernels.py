"""Small numba kernels of the per-packet teleoperation path (4x4 poses, chest frame).

Each replaces a few numpy calls whose Python overhead dominated the session tick and the
command encoding (measured: ``pose_parts`` 104 us, the session tick 48 us per packet).
Readable counterparts: :func:`mocapkit.robot.model.pose_distance`,
:func:`mocapkit.geometry.quat_from_matrix`, :func:`mocapkit.geometry.quat_slerp`; tests
compare them (tests/teleop/test_kernels.py).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def mat_to_quat(R, out):
    """Unit quaternion [w, x, y, z] (w >= 0) of a rotation matrix (Shepperd's method)."""
    m00, m01, m02 = R[0, 0], R[0, 1], R[0, 2]
    m10, m11, m12 = R[1, 0], R[1, 1], R[1, 2]
    m20, m21, m22 = R[2, 0], R[2, 1], R[2, 2]
    tr = m00 + m11 + m22
    if tr >= m00 and tr >= m11 and tr >= m22:
        s = math.sqrt(max(1.0 + tr, 0.0)) * 2.0
        w, x, y, z = 0.25 * s, (m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s
    elif m00 >= m11 and m00 >= m22:
        s = math.sqrt(max(1.0 + m00 - m11 - m22, 0.0)) * 2.0
        w, x, y, z = (m21 - m12) / s, 0.25 * s, (m01 + m10) / s, (m02 + m20) / s
    elif m11 >= m22:
        s = math.sqrt(max(1.0 - m00 + m11 - m22, 0.0)) * 2.0
        w, x, y, z = (m02 - m20) / s, (m01 + m10) / s, 0.25 * s, (m12 + m21) / s
    else:
        s = math.sqrt(max(1.0 - m00 - m11 + m22, 0.0)) * 2.0
        w, x, y, z = (m10 - m01) / s, (m02 + m20) / s, (m12 + m21) / s, 0.25 * s
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if w < 0.0:
        n = -n
    out[0], out[1], out[2], out[3] = w / n, x / n, y / n, z / n


@njit(cache=True)
def rotation_angle(A, B):
    """Angle [rad] of the rotation taking the 3x3 part of A to B (atan2 form)."""
    # R = A^T B
    s0 = s1 = s2 = 0.0
    tr = 0.0
    for k in range(3):
        tr += A[k, 0] * B[k, 0] + A[k, 1] * B[k, 1] + A[k, 2] * B[k, 2]
        # antisymmetric part of A^T B: R[2,1]-R[1,2], R[0,2]-R[2,0], R[1,0]-R[0,1]
        s0 += A[k, 2] * B[k, 1] - A[k, 1] * B[k, 2]
        s1 += A[k, 0] * B[k, 2] - A[k, 2] * B[k, 0]
        s2 += A[k, 1] * B[k, 0] - A[k, 0] * B[k, 1]
    s = 0.5 * math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    return math.atan2(s, 0.5 * (tr - 1.0))


@njit(cache=True)
def pose_error(A, B):
    """(position distance [m], rotation angle [rad]) between two 4x4 poses."""
    dx, dy, dz = A[0, 3] - B[0, 3], A[1, 3] - B[1, 3], A[2, 3] - B[2, 3]
    return math.sqrt(dx * dx + dy * dy + dz * dz), rotation_angle(A, B)


@njit(cache=True)
def apply_offset(T_model, dR, dp, out):
    """out = the reindexed command: R_model dR, p_model + dp (4x4)."""
    for i in range(3):
        for j in range(3):
            out[i, j] = (
                T_model[i, 0] * dR[0, j] + T_model[i, 1] * dR[1, j] + T_model[i, 2] * dR[2, j]
            )
        out[i, 3] = T_model[i, 3] + dp[i]
        out[3, i] = 0.0
    out[3, 3] = 1.0


@njit(cache=True)
def limit_command(cmd, prev, lo, hi, max_step, max_angle, have_prev):
    """Clamp ``cmd`` (4x4, in place) to the workspace box [lo, hi] and, from ``prev``, to a
    translation of ``max_step`` [m] and a rotation of ``max_angle`` [rad]. Returns bit flags:
    1 workspace, 2 speed, 4 rotation speed."""
    flags = 0
    for i in range(3):
        v = cmd[i, 3]
        c = min(max(v, lo[i]), hi[i])
        if c != v:
            cmd[i, 3] = c
            flags |= 1
    if not have_prev:
        return flags
    dx, dy, dz = cmd[0, 3] - prev[0, 3], cmd[1, 3] - prev[1, 3], cmd[2, 3] - prev[2, 3]
    n = math.sqrt(dx * dx + dy * dy + dz * dz)
    if n > max_step:
        f = max_step / n
        cmd[0, 3] = prev[0, 3] + f * dx
        cmd[1, 3] = prev[1, 3] + f * dy
        cmd[2, 3] = prev[2, 3] + f * dz
        flags |= 2
    ang = rotation_angle(prev, cmd)
    if ang > max_angle:
        # rotate from prev towards cmd by max_angle about the step's axis (a slerp)
        R = np.empty((3, 3))
        for i in range(3):
            for j in range(3):
                R[i, j] = prev[0, i] * cmd[0, j] + prev[1, i] * cmd[1, j] + prev[2, i] * cmd[2, j]
        ax0, ax1, ax2 = R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]
        na = math.sqrt(ax0 * ax0 + ax1 * ax1 + ax2 * ax2)
        if na > 1e-12:  # (an exact half turn has no axis here: left as it is)
            ax0, ax1, ax2 = ax0 / na, ax1 / na, ax2 / na
            c, s = math.cos(max_angle), math.sin(max_angle)
            K = np.array([[0.0, -ax2, ax1], [ax2, 0.0, -ax0], [-ax1, ax0, 0.0]])
            step = np.eye(3) + s * K + (1.0 - c) * (K @ K)
            for i in range(3):
                for j in range(3):
                    cmd[i, j] = (
                        prev[i, 0] * step[0, j] + prev[i, 1] * step[1, j] + prev[i, 2] * step[2, j]
                    )
            flags |= 4
    return flags


@njit(cache=True)
def quat_to_mat(q, out):
    """Rotation matrix (3, 3) of a unit quaternion [w, x, y, z] into ``out``."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    out[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    out[0, 1] = 2.0 * (x * y - w * z)
    out[0, 2] = 2.0 * (x * z + w * y)
    out[1, 0] = 2.0 * (x * y + w * z)
    out[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    out[1, 2] = 2.0 * (y * z - w * x)
    out[2, 0] = 2.0 * (x * z - w * y)
    out[2, 1] = 2.0 * (y * z + w * x)
    out[2, 2] = 1.0 - 2.0 * (x * x + y * y)


@njit(cache=True)
def segments_in_chest(q_world_segment, index, chest_index, R_world_chest, chest_in_segment, out):
    """``out[g] = R_world_chest^T R_world_segment[index[g]]`` (G, 3, 3); the chest is the
    segment ``chest_index`` turned by ``chest_in_segment``, or ``R_world_chest`` when
    ``chest_index < 0``. Returns False when an orientation is not finite."""
    for g in range(index.shape[0]):
        for k in range(4):
            if not math.isfinite(q_world_segment[index[g], k]):
                return False
    Rc = np.empty((3, 3))
    if chest_index >= 0:
        for k in range(4):
            if not math.isfinite(q_world_segment[chest_index, k]):
                return False
        Rs = np.empty((3, 3))
        quat_to_mat(q_world_segment[chest_index], Rs)
        for i in range(3):
            for j in range(3):
                Rc[i, j] = (
                    Rs[i, 0] * chest_in_segment[0, j]
                    + Rs[i, 1] * chest_in_segment[1, j]
                    + Rs[i, 2] * chest_in_segment[2, j]
                )
    else:
        Rc[:, :] = R_world_chest
    R = np.empty((3, 3))
    for g in range(index.shape[0]):
        quat_to_mat(q_world_segment[index[g]], R)
        for i in range(3):
            for j in range(3):
                out[g, i, j] = Rc[0, i] * R[0, j] + Rc[1, i] * R[1, j] + Rc[2, i] * R[2, j]
    return True


@njit(cache=True)
def relative_rotvec(q_parent, q_child, r0, r_out, v_out):
    """``r = q_parent^-1 q_child`` into ``r_out`` and the rotation vector of ``r r0^-1``
    (the child's turn relative to the parent since ``r0``, in the parent's frame) into
    ``v_out``; returns its angle [rad]."""
    pw, px, py, pz = q_parent[0], -q_parent[1], -q_parent[2], -q_parent[3]
    cw, cx, cy, cz = q_child[0], q_child[1], q_child[2], q_child[3]
    rw = pw * cw - px * cx - py * cy - pz * cz
    rx = pw * cx + px * cw + py * cz - pz * cy
    ry = pw * cy - px * cz + py * cw + pz * cx
    rz = pw * cz + px * cy - py * cx + pz * cw
    r_out[0], r_out[1], r_out[2], r_out[3] = rw, rx, ry, rz
    ow, ox, oy, oz = r0[0], -r0[1], -r0[2], -r0[3]
    dw = rw * ow - rx * ox - ry * oy - rz * oz
    dx = rw * ox + rx * ow + ry * oz - rz * oy
    dy = rw * oy - rx * oz + ry * ow + rz * ox
    dz = rw * oz + rx * oy - ry * ox + rz * ow
    if dw < 0.0:
        dw, dx, dy, dz = -dw, -dx, -dy, -dz
    s = math.sqrt(dx * dx + dy * dy + dz * dz)
    angle = 2.0 * math.atan2(s, dw)
    f = angle / s if s > 1e-12 else 2.0
    v_out[0], v_out[1], v_out[2] = f * dx, f * dy, f * dz
    return angle


@njit(cache=True)
def pose_from_parts(pos, quat, out):
    """``out`` (4, 4) = the pose of position (3,) [m] and quaternion (4,) (normalised here)."""
    n = math.sqrt(quat[0] ** 2 + quat[1] ** 2 + quat[2] ** 2 + quat[3] ** 2)
    q = np.empty(4)
    for k in range(4):
        q[k] = quat[k] / n
    quat_to_mat(q, out)
    for i in range(3):
        out[i, 3] = pos[i]
        out[3, i] = 0.0
    out[3, 3] = 1.0
