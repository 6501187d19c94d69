"""Rigid-body algorithms on one state (no batch dimension): kinematics, Jacobians, RNEA, CRBA,
ABA, the joint-torque regressor and energies. All reuse the traversal in ``_tree``.

Conventions follow Pinocchio: ``rnea(robot, q, qd, qdd)`` returns joint torques, ``crba`` the
joint-space mass matrix, ``regressor`` the matrix Y with ``rnea = Y @ robot.inertia.ravel()``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from . import _spatial as sp
from ._robot import Robot, check_q
from ._tree import backward_pass, forward_pass, joint_motion, support

_REFERENCES = ("local", "world", "local_world_aligned")


def _checked(robot, **arrays):
    for name, a in arrays.items():
        if a is not None:
            check_q(robot, a, name)
    return [None if a is None else jnp.asarray(a) for a in arrays.values()]


def forward_kinematics(robot: Robot, q):
    """World placements of every body frame.

    **Arguments:** ``q`` (n,) joint positions [rad | m].

    **Returns:** (n, 4, 4) homogeneous transforms of the body frames in the base frame.
    """
    (q,) = _checked(robot, q=q)
    ls = forward_pass(robot, q)
    return jnp.stack([sp.homogeneous(R, p) for R, p in zip(ls.oR, ls.op)])


def _frame_pose(robot: Robot, ls, frame):
    body, k = robot.frame_index(frame)
    if k < 0:
        return body, ls.oR[body], ls.op[body]
    if body < 0:
        return body, robot.frame_R[k], robot.frame_p[k]
    R, p = sp.compose(ls.oR[body], ls.op[body], robot.frame_R[k], robot.frame_p[k])
    return body, R, p


def frame_placement(robot: Robot, q, frame):
    """World placement (4, 4) of a named frame (link, joint or extra frame such as a tool)."""
    (q,) = _checked(robot, q=q)
    _, R, p = _frame_pose(robot, forward_pass(robot, q), frame)
    return sp.homogeneous(R, p)


def jacobian(robot: Robot, q, frame, reference: str = "local_world_aligned"):
    """Geometric Jacobian of a frame, rows ``[linear (3); angular (3)]`` (Pinocchio's order).

    **Arguments:**

    - ``q`` (n,) joint positions.
    - ``frame``: link index, link/joint name, or extra frame name (e.g. a tool).
    - ``reference``: ``"local_world_aligned"`` (velocity of the frame origin and angular velocity in
      base axes; the default), ``"local"`` (both in the frame's own axes) or ``"world"``
      (spatial velocity at the base origin, Pinocchio's WORLD).

    **Returns:** (6, n).
    """
    if reference not in _REFERENCES:
        raise ValueError(f"jacobian: reference must be one of {_REFERENCES}, got '{reference}'")
    (q,) = _checked(robot, q=q)
    ls = forward_pass(robot, q)
    body, oR_f, op_f = _frame_pose(robot, ls, frame)
    cols = []
    anc = set(support(robot, body)) if body >= 0 else set()
    for j in range(robot.nq):
        if j not in anc:
            cols.append(jnp.zeros(6, dtype=op_f.dtype))
            continue
        sw, sv = joint_motion(robot, j)
        zw, zv = ls.oR[j] @ sw, ls.oR[j] @ sv
        if reference == "world":
            lin = zv + jnp.cross(ls.op[j], zw)
        else:
            lin = zv + jnp.cross(zw, op_f - ls.op[j])
        ang = zw
        if reference == "local":
            lin, ang = oR_f.T @ lin, oR_f.T @ ang
        cols.append(jnp.concatenate([lin, ang]))
    return jnp.stack(cols, axis=1)


def _body_forces(robot, ls, f_ext):
    ns, fs = [], []
    for i in range(robot.nq):
        pi = robot.inertia[i]
        hw, hv = sp.inertia_apply(pi, ls.aw[i], ls.av[i])
        mw, mv = sp.inertia_apply(pi, ls.w[i], ls.v[i])
        cw, cv = sp.cross_force(ls.w[i], ls.v[i], mw, mv)
        n_i, f_i = hw + cw, hv + cv
        if f_ext is not None:
            # f_ext rows are [force (3), moment (3)] in body axes, like Pinocchio's fext.
            f_i = f_i - f_ext[i, :3]
            n_i = n_i - f_ext[i, 3:]
        ns.append(n_i)
        fs.append(f_i)
    return ns, fs


def rnea(robot: Robot, q, qd, qdd, f_ext=None):
    """Inverse dynamics by the recursive Newton-Euler algorithm.

    **Arguments:** ``q``, ``qd``, ``qdd`` (n,); ``f_ext`` optional (n, 6) external wrench on each
    body ``[force; moment]`` in body axes about the body origin [N, N m].

    **Returns:** (n,) joint torques/forces ``tau = M(q) qdd + C(q, qd) qd + g(q) - J^T f_ext``.
    """
    q, qd, qdd = _checked(robot, q=q, qd=qd, qdd=qdd)
    ls = forward_pass(robot, q, qd, qdd)
    ns, fs = backward_pass(robot, ls, *_body_forces(robot, ls, f_ext))
    tau = []
    for i in range(robot.nq):
        sw, sv = joint_motion(robot, i)
        tau.append(sp.dot(sw, ns[i]) + sp.dot(sv, fs[i]))
    return jnp.stack(tau)


def nonlinear_effects(robot: Robot, q, qd):
    """Coriolis, centrifugal and gravity torques ``h(q, qd) = rnea(q, qd, 0)``, shape (n,)."""
    return rnea(robot, q, qd, jnp.zeros_like(jnp.asarray(qd)))


def gravity(robot: Robot, q):
    """Gravity torques ``g(q) = rnea(q, 0, 0)``, shape (n,)."""
    z = jnp.zeros_like(jnp.asarray(q))
    return rnea(robot, q, z, z)


def crba(robot: Robot, q):
    """Joint-space mass matrix by the composite rigid-body algorithm, shape (n, n), symmetric."""
    (q,) = _checked(robot, q=q)
    n = robot.nq
    ls = forward_pass(robot, q)
    # composite inertias kept as 10 parameters: the child-to-parent step is linear in them
    Ic = [robot.inertia[i] for i in range(n)]
    for i in reversed(range(n)):
        par = robot.parents[i]
        if par >= 0:
            Ic[par] = Ic[par] + sp.transform_params_fast(Ic[i], ls.R[i], ls.p[i])
    M = [[None] * n for _ in range(n)]
    zero = jnp.zeros((), dtype=robot.inertia.dtype)
    for i in range(n):
        sw, sv = joint_motion(robot, i)
        Fn, Ff = sp.inertia_apply(Ic[i], sw, sv)
        M[i][i] = sp.dot(sw, Fn) + sp.dot(sv, Ff)
        j = i
        while robot.parents[j] >= 0:
            Fn, Ff = sp.force_to_parent(ls.R[j], ls.p[j], Fn, Ff)
            j = robot.parents[j]
            sw, sv = joint_motion(robot, j)
            M[i][j] = M[j][i] = sp.dot(sw, Fn) + sp.dot(sv, Ff)
    return jnp.stack([jnp.stack([zero if e is None else e for e in row]) for row in M])


def aba(robot: Robot, q, qd, tau, f_ext=None):
    """Forward dynamics by the articulated-body algorithm: joint accelerations (n,)."""
    q, qd, tau = _checked(robot, q=q, qd=qd, tau=tau)
    n = robot.nq
    ls = forward_pass(robot, q, qd)
    X = [sp.motion_transform_6x6(ls.R[i], ls.p[i]) for i in range(n)]
    S = [jnp.concatenate(joint_motion(robot, i)) for i in range(n)]
    IA, pA, c = [], [], []
    for i in range(n):
        pi = robot.inertia[i]
        IA.append(sp.inertia_6x6(pi))
        mw, mv = sp.inertia_apply(pi, ls.w[i], ls.v[i])
        bw, bv = sp.cross_force(ls.w[i], ls.v[i], mw, mv)
        b = jnp.concatenate([bw, bv])
        if f_ext is not None:
            b = b - jnp.concatenate([f_ext[i, 3:], f_ext[i, :3]])
        pA.append(b)
        sw, sv = joint_motion(robot, i)
        cw, cv = sp.cross_motion(ls.w[i], ls.v[i], sw * qd[i], sv * qd[i])
        c.append(jnp.concatenate([cw, cv]))
    U, D, u = [None] * n, [None] * n, [None] * n
    for i in reversed(range(n)):
        U[i] = IA[i] @ S[i]
        D[i] = S[i] @ U[i]
        u[i] = tau[i] - S[i] @ pA[i]
        par = robot.parents[i]
        if par >= 0:
            Ia = IA[i] - jnp.outer(U[i], U[i]) / D[i]
            pa = pA[i] + Ia @ c[i] + U[i] * (u[i] / D[i])
            IA[par] = IA[par] + X[i].T @ Ia @ X[i]
            pA[par] = pA[par] + X[i].T @ pa
    a0 = jnp.concatenate([jnp.zeros(3, dtype=tau.dtype), -robot.gravity])
    a = [None] * n
    qdd = [None] * n
    for i in range(n):
        par = robot.parents[i]
        ap = X[i] @ (a0 if par < 0 else a[par]) + c[i]
        qdd[i] = (u[i] - U[i] @ ap) / D[i]
        a[i] = ap + S[i] * qdd[i]
    return jnp.stack(qdd)


def forward_dynamics(robot: Robot, q, qd, tau, f_ext=None, method: str = "aba"):
    """Joint accelerations (n,) from torques: ``qdd = M^-1 (tau - h)``.

    ``method="aba"`` (default; the faster of the two in ``benchmarks/bench_dynamics.py``) or
    ``"crba"`` (mass matrix and Cholesky solve).
    """
    if method == "aba":
        return aba(robot, q, qd, tau, f_ext)
    if method != "crba":
        raise ValueError(f"forward_dynamics: method must be 'aba' or 'crba', got '{method}'")
    M = crba(robot, q)
    h = rnea(robot, q, qd, jnp.zeros_like(jnp.asarray(qd)), f_ext)
    L = jnp.linalg.cholesky(M)
    return jax.scipy.linalg.cho_solve((L, True), jnp.asarray(tau) - h)


def _body_regressor(w, v, aw, av):
    """(6, 10) matrix A with (n; f) = I(pi) a + v x* I(pi) v = A pi (linear in pi)."""

    def f(pi):
        hw, hv = sp.inertia_apply(pi, aw, av)
        mw, mv = sp.inertia_apply(pi, w, v)
        cw, cv = sp.cross_force(w, v, mw, mv)
        return jnp.concatenate([hw + cw, hv + cv])

    return jax.jacfwd(f)(jnp.zeros(10, dtype=w.dtype))


def regressor(robot: Robot, q, qd, qdd):
    """Joint-torque regressor Y (n, 10 n) with ``rnea(q, qd, qdd) == Y @ robot.inertia.ravel()``.

    Parameters per link in Pinocchio's order ``[m, m c_x, m c_y, m c_z, I_xx, I_xy, I_yy, I_xz,
    I_yz, I_zz]``, inertia about the body-frame origin.
    """
    q, qd, qdd = _checked(robot, q=q, qd=qd, qdd=qdd)
    n = robot.nq
    ls = forward_pass(robot, q, qd, qdd)
    S = [joint_motion(robot, i) for i in range(n)]
    zero = jnp.zeros((1, 10), dtype=q.dtype)
    Y = [[zero] * n for _ in range(n)]
    for j in range(n):
        A = _body_regressor(ls.w[j], ls.v[j], ls.aw[j], ls.av[j])
        An, Af = A[:3], A[3:]
        i = j
        while True:
            sw, sv = S[i]
            Y[i][j] = (sw @ An + sv @ Af)[None, :]
            par = robot.parents[i]
            if par < 0:
                break
            R, p = ls.R[i], ls.p[i]
            Af_p = R @ Af
            An = R @ An + sp.skew(p) @ Af_p
            Af = Af_p
            i = par
    return jnp.concatenate([jnp.concatenate(row, axis=1) for row in Y], axis=0)


def kinetic_energy(robot: Robot, q, qd):
    """Kinetic energy [J]: sum over bodies of v^T I v / 2."""
    q, qd = _checked(robot, q=q, qd=qd)
    ls = forward_pass(robot, q, qd)
    T = 0.0
    for i in range(robot.nq):
        mw, mv = sp.inertia_apply(robot.inertia[i], ls.w[i], ls.v[i])
        T = T + 0.5 * (jnp.dot(ls.w[i], mw) + jnp.dot(ls.v[i], mv))
    return T


def potential_energy(robot: Robot, q):
    """Gravitational potential energy [J] relative to the base origin: -sum m g . c."""
    (q,) = _checked(robot, q=q)
    ls = forward_pass(robot, q)
    V = 0.0
    for i in range(robot.nq):
        pi = robot.inertia[i]
        V = V - jnp.dot(robot.gravity, pi[0] * ls.op[i] + ls.oR[i] @ pi[1:4])
    return V
