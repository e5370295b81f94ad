"""Numba kernels for the rigid-body quantities of direct marker control and IK.

Pinocchio is the reference: :func:`flatten` reads the tree (parents, joint placements,
revolute axes, inertias, marker frames) out of the Pinocchio model, and the tests check
every kernel against Pinocchio to 1e-9 (``crba``, ``nonLinearEffects``,
``computeJointJacobians``, frame classical accelerations, ``integrate``). The kernels
exist because reading placements back through Pinocchio's Python bindings costs ~3 µs
per joint, which dominated a frame (see docs/benchmarks.md).

Conventions (as Pinocchio's WORLD): spatial motion ``(v_O, ω)`` with ``v_O`` the velocity
of the body point at the world origin, forces ``(f, n_O)``. Joint 0 is the free-flyer
(q[0:3] position, q[3:7] quaternion x, y, z, w; v[0:6] the twist in the pelvis frame),
joints 1.. are revolute about ``axis`` (in the joint frame), parents before children.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from mocapkit.errors import ConfigError

FloatArray = np.ndarray  # numba kernels: mypy does not track their dtypes

IntArray = np.ndarray


@dataclass(frozen=True)
class FlatModel:
    """A Pinocchio tree (free-flyer + revolute joints) as flat arrays for the kernels."""

    parent: IntArray  # (nj,) parent joint index, -1 for the root
    R0: FloatArray  # (nj, 3, 3) joint placement rotation in the parent joint frame
    p0: FloatArray  # (nj, 3) joint placement translation
    axis: FloatArray  # (nj, 3) revolute axis in the joint frame (unused for the root)
    mass: FloatArray  # (nj,)
    com: FloatArray  # (nj, 3) centre of mass in the joint frame
    inertia: FloatArray  # (nj, 3, 3) rotational inertia about the CoM, joint frame
    marker_joint: IntArray  # (M,) joint index carrying each marker
    marker_offset: FloatArray  # (M, 3) in the joint frame
    gravity: FloatArray  # (3,) m/s^2
    nq: int
    nv: int


def flatten(model: Any, marker_frame_ids: list[int]) -> FlatModel:
    """Read a Pinocchio model (free-flyer root, revolute joints) into a :class:`FlatModel`."""
    import pinocchio as pin

    nj = model.njoints - 1
    parent = np.empty(nj, dtype=np.int64)
    R0 = np.empty((nj, 3, 3))
    p0 = np.empty((nj, 3))
    axis = np.zeros((nj, 3))
    mass = np.empty(nj)
    com = np.empty((nj, 3))
    inertia = np.empty((nj, 3, 3))
    for k in range(1, model.njoints):
        i = k - 1
        jm = model.joints[k]
        short = jm.shortname()
        if i == 0 and short != "JointModelFreeFlyer":
            raise ConfigError(f"joint 1 must be a free-flyer, got {short}")
        if i > 0:
            if short == "JointModelRevoluteUnaligned":
                axis[i] = np.asarray(jm.extract().axis)
            elif short in ("JointModelRX", "JointModelRY", "JointModelRZ"):
                axis[i, "XYZ".index(short[-1])] = 1.0
            else:
                raise ConfigError(f"joint {model.names[k]!r}: unsupported type {short}")
            if jm.idx_v != 6 + i - 1 or jm.idx_q != 7 + i - 1:
                raise ConfigError("joints must be ordered like their configuration entries")
        parent[i] = model.parents[k] - 1
        M = model.jointPlacements[k]
        R0[i] = M.rotation
        p0[i] = M.translation
        Y = model.inertias[k]
        mass[i] = Y.mass
        com[i] = Y.lever
        inertia[i] = Y.inertia
    mj = np.empty(len(marker_frame_ids), dtype=np.int64)
    mo = np.empty((len(marker_frame_ids), 3))
    for m, fid in enumerate(marker_frame_ids):
        frame = model.frames[fid]
        mj[m] = frame.parentJoint - 1
        mo[m] = frame.placement.translation
        if not np.allclose(frame.placement.rotation, np.eye(3)):
            raise ConfigError(f"marker frame {frame.name!r} must not be rotated")
    del pin
    return FlatModel(
        parent,
        R0,
        p0,
        axis,
        mass,
        com,
        inertia,
        mj,
        mo,
        np.asarray(model.gravity.linear, dtype=float).copy(),
        int(model.nq),
        int(model.nv),
    )


# -- small maths ------------------------------------------------------------------------------
@njit(cache=True)
def _cross(a: FloatArray, b: FloatArray) -> FloatArray:
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


@njit(cache=True)
def _mv(A: FloatArray, x: FloatArray) -> FloatArray:
    """A @ x for small matrices without a BLAS call."""
    n, m = A.shape
    out = np.zeros(n)
    for i in range(n):
        acc = 0.0
        for j in range(m):
            acc += A[i, j] * x[j]
        out[i] = acc
    return out


@njit(cache=True)
def _mm(A: FloatArray, B: FloatArray) -> FloatArray:
    """A @ B for small matrices without a BLAS call."""
    n, k = A.shape
    m = B.shape[1]
    out = np.zeros((n, m))
    for i in range(n):
        for j in range(m):
            acc = 0.0
            for l in range(k):
                acc += A[i, l] * B[l, j]
            out[i, j] = acc
    return out


@njit(cache=True)
def _dot(a: FloatArray, b: FloatArray) -> float:
    acc = 0.0
    for i in range(a.shape[0]):
        acc += a[i] * b[i]
    return acc


@njit(cache=True)
def _axis_angle(axis: FloatArray, angle: float) -> FloatArray:
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = axis[0], axis[1], axis[2]
    C = 1.0 - c
    return np.array(
        [
            [c + x * x * C, x * y * C - z * s, x * z * C + y * s],
            [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
            [z * x * C - y * s, z * y * C + x * s, c + z * z * C],
        ]
    )


@njit(cache=True)
def _quat_xyzw_matrix(q: FloatArray) -> FloatArray:
    x, y, z, w = q[0], q[1], q[2], q[3]
    n = np.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


@njit(cache=True)
def forward_kinematics(
    parent: IntArray, R0: FloatArray, p0: FloatArray, axis: FloatArray, q: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """World rotations (nj, 3, 3), origins (nj, 3) and motion subspaces S (nv, 6)."""
    nj = parent.shape[0]
    R = np.empty((nj, 3, 3))
    t = np.empty((nj, 3))
    nv = 6 + nj - 1
    S = np.zeros((nv, 6))
    R[0] = _quat_xyzw_matrix(q[3:7])
    t[0] = q[:3]
    for k in range(3):
        c0, c1, c2 = R[0, 0, k], R[0, 1, k], R[0, 2, k]
        S[k, 0], S[k, 1], S[k, 2] = c0, c1, c2
        S[3 + k, 3], S[3 + k, 4], S[3 + k, 5] = c0, c1, c2
        S[3 + k, 0] = t[0, 1] * c2 - t[0, 2] * c1
        S[3 + k, 1] = t[0, 2] * c0 - t[0, 0] * c2
        S[3 + k, 2] = t[0, 0] * c1 - t[0, 1] * c0
    Rl = np.empty((3, 3))
    for i in range(1, nj):
        p = parent[i]
        # Rl = R0[i] @ rot(axis, q)
        ang = q[6 + i]
        c, sn = np.cos(ang), np.sin(ang)
        x, y, z = axis[i, 0], axis[i, 1], axis[i, 2]
        C = 1.0 - c
        r00, r01, r02 = c + x * x * C, x * y * C - z * sn, x * z * C + y * sn
        r10, r11, r12 = y * x * C + z * sn, c + y * y * C, y * z * C - x * sn
        r20, r21, r22 = z * x * C - y * sn, z * y * C + x * sn, c + z * z * C
        for a in range(3):
            b0, b1, b2 = R0[i, a, 0], R0[i, a, 1], R0[i, a, 2]
            Rl[a, 0] = b0 * r00 + b1 * r10 + b2 * r20
            Rl[a, 1] = b0 * r01 + b1 * r11 + b2 * r21
            Rl[a, 2] = b0 * r02 + b1 * r12 + b2 * r22
        for a in range(3):
            for bb in range(3):
                R[i, a, bb] = (
                    R[p, a, 0] * Rl[0, bb] + R[p, a, 1] * Rl[1, bb] + R[p, a, 2] * Rl[2, bb]
                )
            t[i, a] = (
                R[p, a, 0] * p0[i, 0] + R[p, a, 1] * p0[i, 1] + R[p, a, 2] * p0[i, 2] + t[p, a]
            )
        a0 = R[i, 0, 0] * x + R[i, 0, 1] * y + R[i, 0, 2] * z
        a1 = R[i, 1, 0] * x + R[i, 1, 1] * y + R[i, 1, 2] * z
        a2 = R[i, 2, 0] * x + R[i, 2, 1] * y + R[i, 2, 2] * z
        S[5 + i, 0] = t[i, 1] * a2 - t[i, 2] * a1
        S[5 + i, 1] = t[i, 2] * a0 - t[i, 0] * a2
        S[5 + i, 2] = t[i, 0] * a1 - t[i, 1] * a0
        S[5 + i, 3], S[5 + i, 4], S[5 + i, 5] = a0, a1, a2
    return R, t, S


@njit(cache=True)
def _dof_joint(nj: int) -> IntArray:
    out = np.empty(6 + nj - 1, dtype=np.int64)
    out[:6] = 0
    for i in range(1, nj):
        out[5 + i] = i
    return out


@njit(cache=True)
def _point(R: FloatArray, t: FloatArray, j: int, off: FloatArray) -> tuple[float, float, float]:
    return (
        R[j, 0, 0] * off[0] + R[j, 0, 1] * off[1] + R[j, 0, 2] * off[2] + t[j, 0],
        R[j, 1, 0] * off[0] + R[j, 1, 1] * off[1] + R[j, 1, 2] * off[2] + t[j, 1],
        R[j, 2, 0] * off[0] + R[j, 2, 1] * off[1] + R[j, 2, 2] * off[2] + t[j, 2],
    )


@njit(cache=True)
def marker_kinematics(
    parent: IntArray,
    R: FloatArray,
    t: FloatArray,
    S: FloatArray,
    marker_joint: IntArray,
    marker_offset: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """Marker positions (M, 3) and world-aligned Jacobians (M, 3, nv)."""
    M = marker_joint.shape[0]
    nv = S.shape[0]
    P = np.empty((M, 3))
    J = np.zeros((M, 3, nv))
    for m in range(M):
        j = marker_joint[m]
        x0, x1, x2 = _point(R, t, j, marker_offset[m])
        P[m, 0], P[m, 1], P[m, 2] = x0, x1, x2
        k = j
        while k >= 0:
            lo = 0 if k == 0 else 5 + k
            hi = 6 if k == 0 else 6 + k
            for c in range(lo, hi):
                w0, w1, w2 = S[c, 3], S[c, 4], S[c, 5]
                J[m, 0, c] = S[c, 0] + w1 * x2 - w2 * x1
                J[m, 1, c] = S[c, 1] + w2 * x0 - w0 * x2
                J[m, 2, c] = S[c, 2] + w0 * x1 - w1 * x0
            k = parent[k]
    return P, J


@njit(cache=True)
def marker_positions(
    R: FloatArray, t: FloatArray, marker_joint: IntArray, marker_offset: FloatArray
) -> FloatArray:
    """Marker positions (M, 3) for joint poses R (nj, 3, 3), t (nj, 3)."""
    M = marker_joint.shape[0]
    out = np.empty((M, 3))
    for m in range(M):
        x0, x1, x2 = _point(R, t, marker_joint[m], marker_offset[m])
        out[m, 0], out[m, 1], out[m, 2] = x0, x1, x2
    return out


@njit(cache=True)
def marker_positions_trial(
    parent: IntArray,
    R0: FloatArray,
    p0: FloatArray,
    axis: FloatArray,
    marker_joint: IntArray,
    marker_offset: FloatArray,
    Q: FloatArray,
) -> FloatArray:
    """Marker positions (N, M, 3) at every configuration of Q (N, nq)."""
    N, M = Q.shape[0], marker_joint.shape[0]
    out = np.empty((N, M, 3))
    for f in range(N):
        R, t, _S = forward_kinematics(parent, R0, p0, axis, Q[f])
        for m in range(M):
            x0, x1, x2 = _point(R, t, marker_joint[m], marker_offset[m])
            out[f, m, 0], out[f, m, 1], out[f, m, 2] = x0, x1, x2
    return out


@njit(cache=True)
def _motion_cross_into(v: FloatArray, u: FloatArray, out: FloatArray) -> None:
    """out = (v, w) x_m (u, e) = (w x u + v x e, w x e)."""
    out[0] = v[4] * u[2] - v[5] * u[1] + v[1] * u[5] - v[2] * u[4]
    out[1] = v[5] * u[0] - v[3] * u[2] + v[2] * u[3] - v[0] * u[5]
    out[2] = v[3] * u[1] - v[4] * u[0] + v[0] * u[4] - v[1] * u[3]
    out[3] = v[4] * u[5] - v[5] * u[4]
    out[4] = v[5] * u[3] - v[3] * u[5]
    out[5] = v[3] * u[4] - v[4] * u[3]


@njit(cache=True)
def body_velocities_bias(
    parent: IntArray, S: FloatArray, v: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Spatial velocities V (nj, 6) and velocity-product accelerations A (nj, 6) (q̈ = 0,
    no gravity) of every joint frame, world coordinates at the origin."""
    nj = parent.shape[0]
    V = np.zeros((nj, 6))
    A = np.zeros((nj, 6))
    for c in range(6):
        for e in range(6):
            V[0, e] += S[c, e] * v[c]
    s = np.empty(6)
    cr = np.empty(6)
    for i in range(1, nj):
        p = parent[i]
        for e in range(6):
            s[e] = S[5 + i, e] * v[5 + i]
            V[i, e] = V[p, e] + s[e]
        _motion_cross_into(V[i], s, cr)
        for e in range(6):
            A[i, e] = A[p, e] + cr[e]
    return V, A


@njit(cache=True)
def marker_bias(
    R: FloatArray,
    t: FloatArray,
    V: FloatArray,
    A: FloatArray,
    marker_joint: IntArray,
    marker_offset: FloatArray,
) -> FloatArray:
    """J̇v per marker (M, 3): classical acceleration of the marker at q̈ = 0."""
    M = marker_joint.shape[0]
    out = np.empty((M, 3))
    for m in range(M):
        j = marker_joint[m]
        x = np.array(_point(R, t, j, marker_offset[m]))
        w = V[j, 3:]
        xdot = V[j, :3] + _cross(w, x)
        out[m] = A[j, :3] + _cross(A[j, 3:], x) + _cross(w, xdot)
    return out


# -- dynamics ---------------------------------------------------------------------------------
@njit(cache=True)
def world_inertias(
    R: FloatArray, t: FloatArray, mass: FloatArray, com: FloatArray, inertia: FloatArray
) -> FloatArray:
    """Spatial inertia (nj, 6, 6) of every body at the world origin:
    ``[[m E, -m [c]x], [m [c]x, I_c - m [c]x [c]x]]`` with c the world CoM."""
    nj = mass.shape[0]
    Y = np.zeros((nj, 6, 6))
    RI = np.empty((3, 3))
    for i in range(nj):
        m = mass[i]
        if m == 0.0:
            continue
        c0, c1, c2 = _point(R, t, i, com[i])
        for a in range(3):
            for b in range(3):
                RI[a, b] = (
                    R[i, a, 0] * inertia[i, 0, b]
                    + R[i, a, 1] * inertia[i, 1, b]
                    + R[i, a, 2] * inertia[i, 2, b]
                )
        for a in range(3):
            for b in range(3):
                Y[i, 3 + a, 3 + b] = (
                    RI[a, 0] * R[i, b, 0] + RI[a, 1] * R[i, b, 1] + RI[a, 2] * R[i, b, 2]
                )
            Y[i, a, a] = m
        # [c]x
        X01, X02, X10, X12, X20, X21 = -c2, c1, c2, -c0, -c1, c0
        Y[i, 0, 4], Y[i, 0, 5] = -m * X01, -m * X02
        Y[i, 1, 3], Y[i, 1, 5] = -m * X10, -m * X12
        Y[i, 2, 3], Y[i, 2, 4] = -m * X20, -m * X21
        Y[i, 4, 0], Y[i, 5, 0] = m * X10, m * X20
        Y[i, 3, 1], Y[i, 5, 1] = m * X01, m * X21
        Y[i, 3, 2], Y[i, 4, 2] = m * X02, m * X12
        # - m [c]x [c]x = m (|c|² E - c cᵀ)
        cc = c0 * c0 + c1 * c1 + c2 * c2
        cv = (c0, c1, c2)
        for a in range(3):
            for b in range(3):
                Y[i, 3 + a, 3 + b] += m * ((cc if a == b else 0.0) - cv[a] * cv[b])
    return Y


@njit(cache=True)
def crba(parent: IntArray, S: FloatArray, Y: FloatArray) -> FloatArray:
    """Joint-space inertia matrix A (nv, nv) by composite rigid bodies (world frame)."""
    nj = parent.shape[0]
    nv = S.shape[0]
    Yc = Y.copy()
    for i in range(nj - 1, 0, -1):
        Yc[parent[i]] += Yc[i]
    dof_joint = _dof_joint(nj)
    Amat = np.zeros((nv, nv))
    F = np.empty(6)
    for a in range(nv):
        i = dof_joint[a]
        for e in range(6):
            acc = 0.0
            for f in range(6):
                acc += Yc[i, e, f] * S[a, f]
            F[e] = acc
        k = i
        while k >= 0:
            lo = 0 if k == 0 else 5 + k
            hi = 6 if k == 0 else 6 + k
            for b in range(lo, hi):
                if b <= a or k != i:
                    val = 0.0
                    for e in range(6):
                        val += S[b, e] * F[e]
                    Amat[a, b] = val
                    Amat[b, a] = val
            k = parent[k]
    return Amat


@njit(cache=True)
def nonlinear_effects(
    parent: IntArray, S: FloatArray, Y: FloatArray, V: FloatArray, A: FloatArray, g: FloatArray
) -> FloatArray:
    """b + g (nv,): Coriolis, centrifugal and gravity forces by RNEA with q̈ = 0."""
    nj = parent.shape[0]
    nv = S.shape[0]
    F = np.zeros((nj, 6))
    acc = np.empty(6)
    hv = np.empty(6)
    for i in range(nj):
        for e in range(6):
            acc[e] = A[i, e]
        acc[0] -= g[0]
        acc[1] -= g[1]
        acc[2] -= g[2]
        for e in range(6):
            s1, s2 = 0.0, 0.0
            for f in range(6):
                s1 += Y[i, e, f] * acc[f]
                s2 += Y[i, e, f] * V[i, f]
            F[i, e] = s1
            hv[e] = s2
        # V x_f (Y V): (w x f, v x f + w x n)
        v0, v1, v2, w0, w1, w2 = V[i, 0], V[i, 1], V[i, 2], V[i, 3], V[i, 4], V[i, 5]
        f0, f1, f2, n0, n1, n2 = hv[0], hv[1], hv[2], hv[3], hv[4], hv[5]
        F[i, 0] += w1 * f2 - w2 * f1
        F[i, 1] += w2 * f0 - w0 * f2
        F[i, 2] += w0 * f1 - w1 * f0
        F[i, 3] += v1 * f2 - v2 * f1 + w1 * n2 - w2 * n1
        F[i, 4] += v2 * f0 - v0 * f2 + w2 * n0 - w0 * n2
        F[i, 5] += v0 * f1 - v1 * f0 + w0 * n1 - w1 * n0
    for i in range(nj - 1, 0, -1):
        for e in range(6):
            F[parent[i], e] += F[i, e]
    tau = np.empty(nv)
    for c in range(6):
        tau[c] = _dot(S[c], F[0])
    for i in range(1, nj):
        tau[5 + i] = _dot(S[5 + i], F[i])
    return tau


# -- configuration space ----------------------------------------------------------------------
@njit(cache=True)
def integrate(q: FloatArray, dv: FloatArray) -> FloatArray:
    """q ⊕ dv: the free-flyer moves along exp of its local twist (as pin.integrate)."""
    out = q.copy()
    R = _quat_xyzw_matrix(q[3:7])
    v = dv[:3]
    w = dv[3:6]
    th = np.sqrt(w @ w)
    if th < 1e-8:
        Rexp = np.eye(3) + np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
        Vmat = np.eye(3) + 0.5 * np.array(
            [[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]]
        )
    else:
        ax = w / th
        Rexp = _axis_angle(ax, float(th))
        K = np.array([[0.0, -ax[2], ax[1]], [ax[2], 0.0, -ax[0]], [-ax[1], ax[0], 0.0]])
        Vmat = np.eye(3) + (1 - np.cos(th)) / th * K + (th - np.sin(th)) / th * (K @ K)
    out[:3] = q[:3] + _mv(R, _mv(Vmat, v))
    Rn = _mm(R, Rexp)
    # matrix -> quaternion (x, y, z, w), Shepperd
    tr = Rn[0, 0] + Rn[1, 1] + Rn[2, 2]
    if tr > 0:
        s = np.sqrt(tr + 1.0) * 2
        qw, qx = 0.25 * s, (Rn[2, 1] - Rn[1, 2]) / s
        qy, qz = (Rn[0, 2] - Rn[2, 0]) / s, (Rn[1, 0] - Rn[0, 1]) / s
    elif Rn[0, 0] > Rn[1, 1] and Rn[0, 0] > Rn[2, 2]:
        s = np.sqrt(1.0 + Rn[0, 0] - Rn[1, 1] - Rn[2, 2]) * 2
        qw, qx = (Rn[2, 1] - Rn[1, 2]) / s, 0.25 * s
        qy, qz = (Rn[0, 1] + Rn[1, 0]) / s, (Rn[0, 2] + Rn[2, 0]) / s
    elif Rn[1, 1] > Rn[2, 2]:
        s = np.sqrt(1.0 + Rn[1, 1] - Rn[0, 0] - Rn[2, 2]) * 2
        qw, qx = (Rn[0, 2] - Rn[2, 0]) / s, (Rn[0, 1] + Rn[1, 0]) / s
        qy, qz = 0.25 * s, (Rn[1, 2] + Rn[2, 1]) / s
    else:
        s = np.sqrt(1.0 + Rn[2, 2] - Rn[0, 0] - Rn[1, 1]) * 2
        qw, qx = (Rn[1, 0] - Rn[0, 1]) / s, (Rn[0, 2] + Rn[2, 0]) / s
        qy, qz = (Rn[1, 2] + Rn[2, 1]) / s, 0.25 * s
    if qw < 0:  # keep the hemisphere of the input for continuity
        qx, qy, qz, qw = -qx, -qy, -qz, -qw
    if q[3:7] @ np.array([qx, qy, qz, qw]) < 0:
        qx, qy, qz, qw = -qx, -qy, -qz, -qw
    out[3], out[4], out[5], out[6] = qx, qy, qz, qw
    out[7:] = q[7:] + dv[6:]
    return out


@njit(cache=True)
def dynamics_terms(
    parent: IntArray,
    R0: FloatArray,
    p0: FloatArray,
    axis: FloatArray,
    mass: FloatArray,
    com: FloatArray,
    inertia: FloatArray,
    gravity: FloatArray,
    q: FloatArray,
    v: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Everything one control step needs: R, t, S, V, Abias, A (mass matrix), b + g."""
    R, t, S = forward_kinematics(parent, R0, p0, axis, q)
    V, Ab = body_velocities_bias(parent, S, v)
    Y = world_inertias(R, t, mass, com, inertia)
    Amat = crba(parent, S, Y)
    h = nonlinear_effects(parent, S, Y, V, Ab, gravity)
    return R, t, S, V, Ab, Amat, h
