"""Analytic first-order derivatives of inverse and forward dynamics (one state; vmap for batches).

The recursive algorithm of Carpentier and Mansard ("Analytical derivatives of rigid body
dynamics algorithms", RSS 2018; Pinocchio's ``rnea-derivatives``), written on the scalarised
algebra of ``_scalar``. Every quantity is taken in the base frame, about the base origin, so that
composite (subtree) quantities are plain sums and a joint's motion acts on its whole subtree as
one spatial cross product.

Moving joint ``j`` (world motion axis ``S_j``, parent ``p``) changes a body ``k`` of its subtree
by the rigid motion ``S_j x`` plus, for its velocity and acceleration, terms that do not depend
on ``k`` except through ``V_k``:

* ``d V_k/d q_j = S_j x V_k + e_j`` with ``e_j = V_p x S_j``,
* ``d A_k/d q_j = S_j x A_k + c_j - V_k x e_j`` with ``c_j = A_p x S_j + V_p x e_j``,
* ``d V_k/d qd_j = S_j``, ``d A_k/d qd_j = 2 e_j - V_k x S_j``.

The ``V_k``-dependent parts meet the body force ``F_k = Y_k A_k + V_k x* Y_k V_k`` through
``D_k x = Ydot_k x + x x* h_k`` (``Ydot_k``: the time derivative of the world inertia,
``h_k = Y_k V_k``), which sums over a subtree like the inertia does. Since the rigid part of the
change leaves ``S_i . Fc_i`` unchanged, for ``i`` in the subtree of ``j``

    d tau_i / d q_j = S_i . (Yc_i c_j + Dc_i e_j),   d tau_i / d qd_j = S_i . (2 Yc_i e_j + Dc_i S_j),

and for ``i`` a strict ancestor of ``j`` the change of the subtree force ``Fc_j`` is projected:
``S_i . (Yc_j c_j + Dc_j e_j + S_j x* Fc_j)`` and ``S_i . (2 Yc_j e_j + Dc_j S_j)``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from . import _coupling as cp
from . import _scalar as s
from ._checks import guard, has_inertia, moving_inertia
from ._coupling import checked as _checked
from ._robot import PRISMATIC, Robot
from ._tree import consts, joint_cos_sin, transform


def _dtype():
    return jnp.result_type(float)


def _dot6(a, b):
    """Pairing of a force (n, f) with a motion (w, v): n.w + f.v."""
    return s.add(s.dot(a[0], b[0]), s.dot(a[1], b[1]))


def _add6(a, b):
    return a[0] + b[0], a[1] + b[1]


def _inertia_rate(Y: s.Inertia, w: s.V3, v: s.V3) -> s.Inertia:
    """Time derivative of a world inertia (m, h, I about the origin) moving with spatial velocity
    (w, v): hdot = m v + w x h, Idot = X + X^T with X = [w]x I - [v]x [h]x (mass constant)."""
    X = s.skew(w).mm(Y.I) + s.skew(-v).mm(s.skew(Y.h))
    Idot = X + X.T
    return s.Inertia(0.0, v.scale(Y.m) + s.cross(w, Y.h), Idot)


def _world_pass(robot: Robot, c, q, qd, qdd, f_ext):
    """Per body, in base axes about the base origin: motion axis S, velocity V, acceleration A
    (gravity as a base acceleration), inertia Y, its rate Ydot, momentum h and force F."""
    n = robot.nq
    a0 = (s.ZERO, -c.gravity)
    S, V, A, Y, Yd, h, F, P = ([None] * n for _ in range(8))
    cs = joint_cos_sin(robot, q)
    for i in range(n):
        par = robot.parents[i]
        # placements composed here, not by _tree.walk, whose world placements carry no fence: every
        # consumer would recompute the chain of rotations (measured: 70 sines per sine)
        R, p = transform(robot, c, i, q[i], cs[i])
        oR, op = (R, p) if par < 0 else (P[par][0].mm(R), P[par][1] + P[par][0].mv(p))
        oR, op = P[i] = s.barrier(oR, op, fence=c.fence)
        ax = oR.mv(c.axis[i])
        S[i] = (s.ZERO, ax) if robot.joint_types[i] == PRISMATIC else (ax, s.cross(op, ax))
        Vp, Ap = ((s.ZERO, s.ZERO), a0) if par < 0 else (V[par], A[par])
        V[i] = (Vp[0] + S[i][0].scale(qd[i]), Vp[1] + S[i][1].scale(qd[i]))
        bw, bv = s.cross_motion(*V[i], S[i][0].scale(qd[i]), S[i][1].scale(qd[i]))
        A[i] = (Ap[0] + S[i][0].scale(qdd[i]) + bw, Ap[1] + S[i][1].scale(qdd[i]) + bv)
        S[i], V[i], A[i] = _fence6(c.fence, S[i], V[i], A[i])
        (Y[i],) = _fence6(c.fence, c.inertia[i].to_parent(oR, op))
        (h[i],) = _fence6(c.fence, Y[i].apply(*V[i]))
        Yd[i] = _inertia_rate(Y[i], *V[i])
        fn, ff = _add6(Y[i].apply(*A[i]), s.cross_force(*V[i], *h[i]))
        if f_ext is not None:
            # rows [force (3), moment (3)] in body axes about the body origin, as in rnea
            fb, nb = oR.mv(s.V3(f_ext[i, 0], f_ext[i, 1], f_ext[i, 2])), oR.mv(s.V3(f_ext[i, 3], f_ext[i, 4], f_ext[i, 5]))
            fn, ff = fn - nb - s.cross(op, fb), ff - fb
        F[i] = (fn, ff)
        Y[i], Yd[i], h[i], F[i] = _fence6(c.fence, Y[i], Yd[i], h[i], F[i])
    return S, V, A, Y, Yd, h, F


def _fence6(fence, *objs):
    """:func:`_scalar.barrier` through pairs of V3 (spatial vectors) and Inertia objects."""
    flat, shape = [], []
    for o in objs:
        if isinstance(o, tuple):
            flat.extend(o)
            shape.append(len(o))
        else:
            flat.append(o)
            shape.append(0)
    vals = s.barrier(*flat, fence=fence)
    out, k = [], 0
    for m in shape:
        if m:
            out.append(tuple(vals[k : k + m]))
            k += m
        else:
            out.append(vals[k])
            k += 1
    return out


def _subtree_sums(robot, c, *per_body):
    """Subtree sums of per-body quantities (world frame: no transforms)."""
    out = [list(x) for x in per_body]
    for i in reversed(range(robot.nq)):
        par = robot.parents[i]
        if par >= 0:
            vals = [x[par] + x[i] if isinstance(x[i], s.Inertia) else _add6(x[par], x[i]) for x in out]
            for x, v in zip(out, _fence6(c.fence, *vals)):
                x[par] = v
    return out


def _kernel(robot: Robot, q, qd, qdd, f_ext, tau=None):
    """(dtau_dq, dtau_dqd, M, L, fence) as nested lists of scalars (fence: see _scalar.barrier). With ``tau`` given (and ``qdd=None``)
    the accelerations are first solved from ``M qdd = tau - h`` on the same pass, and ``L`` is the
    Cholesky factor of M (else None)."""
    n = robot.nq
    c = consts(robot)
    if c.fence is None and isinstance(q, jax.core.Tracer):  # compiled, not run op by op
        # XLA:CPU drops optimization barriers before fusing, and then recomputes every shared
        # per-body vector in each of its O(n^2) consumers; conditionals on a run-time predicate stay
        # boundaries (see _scalar.barrier). NaN q never passes the argument checks, so the branch
        # that returns NaN is never taken.
        from equinox.internal import unvmap_any

        c = c._replace(fence=unvmap_any(jnp.isnan(q[0])))
    S, V, A, Y, Yd, h, F = _world_pass(robot, c, q, qd, [0.0] * n if tau is not None else qdd, f_ext)
    Yc, Ydc, hc, Fc = _subtree_sums(robot, c, Y, Yd, h, F)
    Ag = [_fence6(c.fence, Yc[j].apply(*S[j]))[0] for j in range(n)]
    M = [[0.0] * n for _ in range(n)]
    for i in range(n):
        j = i
        while j >= 0:
            M[i][j] = M[j][i] = _dot6(Ag[i], S[j])
            j = robot.parents[j]
    L = None
    if tau is not None:
        L = _cholesky(M, c.fence)
        # qdd = M^-1 (tau - h); the bodies' accelerations and forces then move by S qdd
        qdd = [x[0] for x in _cholesky_solve(L, [[s.sub(tau[i], _dot6(Fc[i], S[i]))] for i in range(n)], c.fence)]
        dA = [None] * n
        for i in range(n):
            par = robot.parents[i]
            Sq = (S[i][0].scale(qdd[i]), S[i][1].scale(qdd[i]))
            dA[i] = Sq if par < 0 else _add6(dA[par], Sq)
            dA[i], A[i], F[i] = _fence6(c.fence, dA[i], _add6(A[i], dA[i]), _add6(F[i], Y[i].apply(*dA[i])))
        (Fc,) = _subtree_sums(robot, c, F)
    a0 = (s.ZERO, -c.gravity)
    # per joint j: e_j, c_j; the rows' vectors Ag_i = Yc_i S_i, G_i = Dc_i^T S_i; the columns'
    # subtree force changes dFq_j, dFv_j (for strict ancestors)
    G, e, cj, dFq, dFv = ([None] * n for _ in range(5))
    for j in range(n):
        par = robot.parents[j]
        Sj = S[j]
        if par < 0:
            e[j] = (s.ZERO, s.ZERO)
            cj[j] = s.cross_motion(*a0, *Sj)
        else:
            e[j] = s.cross_motion(*V[par], *Sj)
            cj[j] = _add6(s.cross_motion(*A[par], *Sj), s.cross_motion(*V[par], *e[j]))
        e[j], cj[j] = _fence6(c.fence, e[j], cj[j])
        # Dc^T S = Ydot_c S - S x* hc  (Ydot symmetric; the transpose of x -> x x* h is -(. x* h))
        yS, xS = _fence6(c.fence, Ydc[j].apply(*Sj), s.cross_force(*Sj, *hc[j]))
        G[j] = (yS[0] - xS[0], yS[1] - xS[1])
        # Dc e = Ydot_c e + e x* hc ;  Dc S = Ydot_c S + S x* hc
        De = _add6(Ydc[j].apply(*e[j]), s.cross_force(*e[j], *hc[j]))
        DS = _add6(yS, xS)
        Yce = Yc[j].apply(*e[j])
        dFq[j] = _add6(_add6(Yc[j].apply(*cj[j]), De), s.cross_force(*Sj, *Fc[j]))
        dFv[j] = _add6((Yce[0].scale(2.0), Yce[1].scale(2.0)), DS)
        G[j], dFq[j], dFv[j] = _fence6(c.fence, G[j], dFq[j], dFv[j])
    dq = [[0.0] * n for _ in range(n)]
    dv = [[0.0] * n for _ in range(n)]
    for i in range(n):
        j = i
        while j >= 0:  # j: i and its ancestors
            dq[i][j] = s.add(_dot6(Ag[i], cj[j]), _dot6(G[i], e[j]))
            dv[i][j] = s.add(s.mul(2.0, _dot6(Ag[i], e[j])), _dot6(G[i], S[j]))
            if j != i:
                dq[j][i] = _dot6(dFq[i], S[j])
                dv[j][i] = _dot6(dFv[i], S[j])
            j = robot.parents[j]
    return dq, dv, M, L, c.fence


def _matrix(rows, dtype):
    n = len(rows)
    return s.stack([x for row in rows for x in row], dtype).reshape(n, n)


def rnea_derivatives(robot: Robot, q, qd, qdd, f_ext=None):
    """Partial derivatives of inverse dynamics :func:`jflex.rnea` (Carpentier and Mansard's
    recursive algorithm, as Pinocchio's ``computeRNEADerivatives``).

    **Arguments:** ``q``, ``qd``, ``qdd`` (n,) joint positions [rad | m], velocities and
    accelerations; ``f_ext`` optional (n, 6) external wrench on each body ``[force; moment]`` in
    body axes about the body origin [N, N m], held fixed in the body.

    **Returns:** ``(dtau_dq, dtau_dqd, dtau_dqdd)``, each (n, n) with entry ``[i, j] = d tau_i /
    d x_j``; ``dtau_dqdd`` is the mass matrix ``M(q)``. One state: ``jax.vmap`` for a batch.

    Raises like :func:`jflex.rnea`.
    """
    has_inertia("rnea_derivatives", robot)
    q, qd, qdd, f_ext = _checked("rnea_derivatives", robot, q=q, qd=qd, qdd=qdd, f_ext=f_ext)
    if cp.coupled(robot):  # tau = G^T tau_tree(G q + b, G qd, G qdd): G^T D G for each
        G = cp.matrix(robot)
        full = rnea_derivatives(cp.tree(robot), cp.positions(robot, q), cp.rates(robot, qd), cp.rates(robot, qdd), f_ext)
        return tuple(G.T @ D @ G for D in full)
    dq, dv, M, _, _ = _kernel(robot, q, qd, qdd, f_ext)
    dt = _dtype()
    return _matrix(dq, dt), _matrix(dv, dt), _matrix(M, dt)


def _cholesky(M, fence=None):
    """Lower Cholesky factor of a symmetric positive definite M (nested lists of scalars), unrolled
    so that under vmap every step is one elementwise pass over the batch (no batched LAPACK calls
    on tiny matrices). Not positive definite: NaN on the diagonal from the failing pivot on."""
    n = len(M)
    L = [[0.0] * n for _ in range(n)]
    for j in range(n):
        L[j][j] = jnp.sqrt(s.sub(M[j][j], s.sum_(*(s.mul(L[j][k], L[j][k]) for k in range(j)))))
        inv = 1.0 / L[j][j]
        for i in range(j + 1, n):
            L[i][j] = s.mul(s.sub(M[i][j], s.sum_(*(s.mul(L[i][k], L[j][k]) for k in range(j)))), inv)
        # a fence per column: later columns read every entry (see _kernel on fusion)
        col = s.barrier(*(L[i][j] for i in range(j, n)), fence=fence)
        for i in range(j, n):
            L[i][j] = col[i - j]
    return L


def _cholesky_solve(L, B, fence=None):
    """M^-1 B from the Cholesky factor L of M, for B (n x m) nested lists of scalars."""
    n, m = len(L), len(B[0])
    inv = [1.0 / L[i][i] for i in range(n)]
    Y = [[None] * m for _ in range(n)]
    for i in range(n):
        for c in range(m):
            Y[i][c] = s.mul(s.sub(B[i][c], s.sum_(*(s.mul(L[i][k], Y[k][c]) for k in range(i)))), inv[i])
        Y[i] = list(s.barrier(*Y[i], fence=fence))
    X = [[None] * m for _ in range(n)]
    for i in reversed(range(n)):
        for c in range(m):
            X[i][c] = s.mul(s.sub(Y[i][c], s.sum_(*(s.mul(L[k][i], X[k][c]) for k in range(i + 1, n)))), inv[i])
        X[i] = list(s.barrier(*X[i], fence=fence))
    return X


def aba_derivatives(robot: Robot, q, qd, tau, f_ext=None):
    """Partial derivatives of forward dynamics :func:`jflex.aba` (as Pinocchio's
    ``computeABADerivatives``): ``qdd = M^-1 (tau - h)`` is solved on the same pass, then
    ``d qdd = -M^-1 d tau_rnea`` at that ``qdd``.

    **Arguments:** ``q``, ``qd``, ``tau`` (n,) joint positions, velocities and torques/forces;
    ``f_ext`` optional (n, 6) as in :func:`rnea_derivatives`.

    **Returns:** ``(dqdd_dq, dqdd_dqd, dqdd_dtau)``, each (n, n); ``dqdd_dtau`` is ``M(q)^-1``.

    Raises like :func:`jflex.aba`: :class:`jflex.DataError` for NaN/inf arguments,
    :class:`jflex.ParameterError` for a joint that moves no inertia (a singular mass matrix; at run
    time inside ``jit``).
    """
    fn = "aba_derivatives"
    if cp.coupled(robot):
        return _coupled_aba_derivatives(robot, q, qd, tau, f_ext)
    moving_inertia(fn, robot)
    q, qd, tau, f_ext = _checked(fn, robot, q=q, qd=qd, tau=tau, f_ext=f_ext)
    n = robot.nq
    dq, dv, M, L, fence = _kernel(robot, q, qd, None, f_ext, tau=tau)
    B = [[1.0 if c == i else 0.0 for c in range(n)] + [s.mul(-1.0, x) for x in dq[i]] + [s.mul(-1.0, x) for x in dv[i]]
         for i in range(n)]
    X = _cholesky_solve(L, B, fence)
    dt = _dtype()
    out = jnp.stack([_matrix([row[k * n : (k + 1) * n] for row in X], dt) for k in (1, 2, 0)])
    out = guard(out, [~jnp.all(jnp.isfinite(s.stack([L[i][i] for i in range(n)], dt)))], [
        f"{fn}: the mass matrix is not positive definite (a joint moves no inertia?); check robot.inertia"])
    return out[0], out[1], out[2]


def _coupled_aba_derivatives(robot: Robot, q, qd, tau, f_ext):
    """:func:`aba_derivatives` of a robot with coupled joints: ``qdd`` by the coupled mass matrix,
    then ``d qdd = -M^-1 d tau_rnea`` at that ``qdd`` with the coupled inverse-dynamics derivatives."""
    from ._dynamics import _fd_crba

    fn = "aba_derivatives"
    has_inertia(fn, robot)
    q, qd, tau, f_ext = _checked(fn, robot, q=q, qd=qd, tau=tau, f_ext=f_ext)
    qdd = _fd_crba(robot, q, qd, tau, f_ext, fn)
    dq, dv, M = rnea_derivatives(robot, q, qd, qdd, f_ext)
    L = jnp.linalg.cholesky(M)
    X = jax.scipy.linalg.cho_solve((L, True), jnp.concatenate([dq, dv, jnp.eye(robot.nq, dtype=M.dtype)], axis=1))
    n = robot.nq
    return -X[:, :n], -X[:, n : 2 * n], X[:, 2 * n :]
