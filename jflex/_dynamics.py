"""Rigid-body algorithms on one state (no batch dimension): kinematics, Jacobians, RNEA, CRBA,
ABA, the joint-torque regressor and energies. All reuse the traversal in ``_tree`` and the
scalarised algebra in ``_scalar``.

Conventions follow Pinocchio: ``rnea(robot, q, qd, qdd)`` returns joint torques, ``crba`` the
joint-space mass matrix, ``regressor`` the matrix Y with ``rnea = Y @ robot.inertia.ravel()``.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from . import _coupling as cp
from . import _scalar as s
from . import _spatial as sp
from ._coupling import checked as _checked
from ._checks import guard, has_inertia, moving_inertia
from ._derivatives import _kernel, _matrix, aba_derivatives
from ._errors import ParameterError
from ._robot import PRISMATIC, Robot
from ._tree import accumulate, consts, host, motion, support, walk

_REFERENCES = ("local", "world", "local_world_aligned")


def _dtype():
    return jnp.result_type(float)


def forward_kinematics(robot: Robot, q):
    """World placements of every body frame.

    **Arguments:** ``q`` (n,) joint positions [rad | m].

    **Returns:** (n, 4, 4) homogeneous transforms of the body frames in the base frame (one per
    joint of the tree, coupled joints included).
    """
    (q,) = _checked("forward_kinematics", robot, q=q)
    if cp.coupled(robot):
        robot, q = cp.tree(robot), cp.positions(robot, q)
    ls = walk(robot, consts(robot, inertia=False), q, world=True)
    dt = _dtype()
    return jnp.stack([sp.homogeneous(R.array().astype(dt), p.array().astype(dt)) for R, p in zip(ls.oR, ls.op)])


def _frame_pose(robot: Robot, ls, frame):
    """(body, R, p) of a frame in the base, scalarised."""
    body, k = robot.frame_index(frame)
    if k < 0:
        return body, ls.oR[body], ls.op[body]
    fR, fp = s.M33.of(host(robot.frame_R)[k]), s.V3.of(host(robot.frame_p)[k])
    if body < 0:
        return body, fR, fp
    return body, ls.oR[body].mm(fR), ls.op[body] + ls.oR[body].mv(fp)


def frame_placement(robot: Robot, q, frame):
    """World placement (4, 4) of a named frame (link, joint or extra frame such as a tool)."""
    (q,) = _checked("frame_placement", robot, q=q)
    if cp.coupled(robot):
        robot, q = cp.tree(robot), cp.positions(robot, q)
    _, R, p = _frame_pose(robot, walk(robot, consts(robot, inertia=False), q, world=True), frame)
    dt = _dtype()
    return sp.homogeneous(R.array().astype(dt), p.array().astype(dt))


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
        raise ParameterError(f"jacobian: reference must be one of {_REFERENCES}, got '{reference}'")
    (q,) = _checked("jacobian", robot, q=q)
    if cp.coupled(robot):  # a coupled joint's column adds to its leader's, times the multiplier
        return jacobian(cp.tree(robot), cp.positions(robot, q), frame, reference) @ cp.matrix(robot)
    c = consts(robot, inertia=False)
    ls = walk(robot, c, q, world=True)
    body, oR_f, op_f = _frame_pose(robot, ls, frame)
    anc = set(support(robot, body)) if body >= 0 else set()
    cols = []
    for j in range(robot.nq):
        if j not in anc:
            cols.append([0.0] * 6)
            continue
        sw, sv = motion(robot, c, j)
        zw, zv = ls.oR[j].mv(sw), ls.oR[j].mv(sv)
        if reference == "world":
            lin = zv + s.cross(ls.op[j], zw)
        else:
            lin = zv + s.cross(zw, op_f - ls.op[j])
        ang = zw
        if reference == "local":
            lin, ang = oR_f.tv(lin), oR_f.tv(ang)
        cols.append(list(lin) + list(ang))
    dt = _dtype()
    return jnp.stack([s.stack(col, dt) for col in cols], axis=1)


def _body_forces(robot, c, ls, f_ext):
    ns, fs = [], []
    for i in range(robot.nq):
        I = c.inertia[i]
        hw, hv = I.apply(ls.aw[i], ls.av[i])
        mw, mv = I.apply(ls.w[i], ls.v[i])
        cw, cv = s.cross_force(ls.w[i], ls.v[i], mw, mv)
        n_i, f_i = hw + cw, hv + cv
        if f_ext is not None:
            # f_ext rows are [force (3), moment (3)] in body axes, like Pinocchio's fext.
            f_i = f_i - s.V3(f_ext[i, 0], f_ext[i, 1], f_ext[i, 2])
            n_i = n_i - s.V3(f_ext[i, 3], f_ext[i, 4], f_ext[i, 5])
        ns.append(n_i)
        fs.append(f_i)
    return ns, fs


def rnea(robot: Robot, q, qd, qdd, f_ext=None):
    """Inverse dynamics by the recursive Newton-Euler algorithm.

    **Arguments:** ``q``, ``qd``, ``qdd`` (n,); ``f_ext`` optional (n, 6) external wrench on each
    body ``[force; moment]`` in body axes about the body origin [N, N m].

    **Returns:** (n,) joint torques/forces ``tau = M(q) qdd + C(q, qd) qd + g(q) - J^T f_ext``.

    Forward-mode derivatives in ``q``, ``qd``, ``qdd`` (``jax.jvp``, ``jax.jacfwd``) come from the
    analytic recursion of :func:`jflex.rnea_derivatives` (a custom JVP, for a robot that is not
    itself traced); in the robot's parameters and ``f_ext``, from plain forward mode.

    Raises :class:`jflex.DataError` for NaN/inf arguments (at run time inside ``jit``) and
    :class:`jflex.ParameterError` for a robot without any inertial parameters.
    """
    has_inertia("rnea", robot)
    q, qd, qdd, f_ext = _checked("rnea", robot, q=q, qd=qd, qdd=qdd, f_ext=f_ext)
    if cp.coupled(robot):  # tau = G^T tau_tree (virtual work)
        full = rnea(cp.tree(robot), cp.positions(robot, q), cp.rates(robot, qd), cp.rates(robot, qdd), f_ext)
        return cp.project(robot, full)
    return (_rnea_analytic if _concrete(robot) else _rnea_core)(robot, q, qd, qdd, f_ext)


def _rnea(robot: Robot, q, qd, qdd, f_ext, fn, check=True):
    """:func:`rnea` without the inertia check (a :class:`jflex.Model`'s effects may carry all the
    mass of a kinematic robot); ``fn`` names the caller in messages; ``check=False``: the caller
    checked the arguments."""
    if check:
        q, qd, qdd, f_ext = _checked(fn, robot, q=q, qd=qd, qdd=qdd, f_ext=f_ext)
    if cp.coupled(robot):
        full = _rnea_core(cp.tree(robot), cp.positions(robot, q), cp.rates(robot, qd), cp.rates(robot, qdd), f_ext)
        return cp.project(robot, full)
    return _rnea_core(robot, q, qd, qdd, f_ext)


def _state_derivative(core, matrices):
    """``core(robot, x1, x2, x3, f_ext)`` whose forward-mode derivative in the state ``x1, x2, x3``
    is ``sum_k matrices(...)[k] @ dx_k`` (the analytic recursions of :mod:`._derivatives`: one pass
    for every direction, where forward mode pushes each tangent through the whole traversal);
    tangents in ``f_ext`` take plain forward mode. The robot is held as a constant of the rule
    (``nondiff_argnums``): its arrays stay concrete while the kernels are traced, which the
    unrolled kernels fold (a robot traced as an argument of the rule made the batched RNEA 1.7x
    slower); so this applies only to a robot that is not traced (see :func:`_concrete`), and
    derivatives in the robot's parameters take plain forward mode through ``core``."""

    @functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
    def f(robot, x1, x2, x3, f_ext):
        return core(robot, x1, x2, x3, f_ext)

    def rule(robot, primals, tangents):
        zero = lambda t: isinstance(t, jax.custom_derivatives.SymbolicZero)
        if not all(zero(t) for t in jax.tree_util.tree_leaves(tangents[3], is_leaf=zero)):
            dense = [jax.tree_util.tree_map(_instantiate, p, t, is_leaf=zero) for p, t in zip(primals, tangents)]
            return jax.jvp(lambda *a: core(robot, *a), primals, tuple(dense))
        y = core(robot, *primals)
        flagged = isinstance(y, tuple)  # (value, check): the check (0 or 1) has no derivative
        value = y[0] if flagged else y
        out = jnp.zeros_like(value)
        for mat, t in zip(matrices(robot, *primals), tangents[:3]):
            if not zero(t):
                out = out + mat @ t
        return y, ((out, jnp.zeros_like(y[1])) if flagged else out)

    f.defjvp(rule, symbolic_zeros=True)
    return f


def _concrete(robot) -> bool:
    """Whether none of the robot's arrays is traced (by jit, vmap or a derivative in them)."""
    return not any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(robot))


def _instantiate(p, t):
    if not isinstance(t, jax.custom_derivatives.SymbolicZero):
        return t
    p = jnp.asarray(p)
    return jnp.zeros_like(p) if jnp.issubdtype(p.dtype, jnp.inexact) else np.zeros(p.shape, jax.dtypes.float0)


def _rnea_matrices(robot, q, qd, qdd, f_ext):
    dq, dv, M, _, _ = _kernel(robot, q, qd, qdd, f_ext)
    return tuple(_matrix(m, _dtype()) for m in (dq, dv, M))


# only the public rnea and aba carry it: reverse mode transposes the full matrices (jax.grad 1.6x
# slower than through the traversal) and the kernels compile longer, which the library's own
# linearisations and fits need not pay
_rnea_analytic = _state_derivative(lambda *a: _rnea_core(*a), _rnea_matrices)


def _rnea_core(robot: Robot, q, qd, qdd, f_ext):
    c = consts(robot)
    ls = walk(robot, c, q, qd, qdd)
    ns, fs = accumulate(robot, ls, *_body_forces(robot, c, ls, f_ext), fence=c.fence)
    tau = []
    for i in range(robot.nq):
        sw, sv = motion(robot, c, i)
        tau.append(s.add(s.dot(sw, ns[i]), s.dot(sv, fs[i])))
    return s.stack(tau, _dtype())


def nonlinear_effects(robot: Robot, q, qd):
    """Coriolis, centrifugal and gravity torques ``h(q, qd) = rnea(q, qd, 0)``, shape (n,)."""
    has_inertia("nonlinear_effects", robot)
    return _rnea(robot, q, qd, jnp.zeros_like(jnp.asarray(qd)), None, "nonlinear_effects")


def gravity(robot: Robot, q):
    """Gravity torques ``g(q) = rnea(q, 0, 0)``, shape (n,)."""
    has_inertia("gravity", robot)
    z = jnp.zeros_like(jnp.asarray(q))
    return _rnea(robot, q, z, z, None, "gravity")


def _inertia_to_parent(robot, c, i, ls, I):
    """Body i's (composite) inertia about its parent's frame. For a revolute joint about +-z (every
    DH joint, most URDF joints) the joint rotation is applied first, in closed form, and the
    constant placement after it, where trace-time folding makes it nearly free."""
    rz = _z_cos_sin(robot, c, i, ls.cs[i])
    if rz is not None:
        return I.rotated_z(*rz).to_parent(c.Rpl[i], c.ppl[i])
    return I.to_parent(ls.R[i], ls.p[i])


def _z_cos_sin(robot, c, i, cs):
    """``(cos, sin)`` of body i's rotation about its placement's z when joint i is revolute about
    +-z (every DH joint, most URDF joints), else None; ``cs``: the tree walk's ``(cos q_i, sin q_i)``. The test is on trace-time floats: a traced
    axis (gradients in the robot) takes the general path."""
    ax = c.axis[i]
    if robot.joint_types[i] == PRISMATIC or not (s._is(ax.x, 0.0) and s._is(ax.y, 0.0)):
        return None
    if not (s._is(ax.z, 1.0) or s._is(ax.z, -1.0)):
        return None
    cos, sin = cs
    return s.barrier(cos, sin if s._is(ax.z, 1.0) else -sin, fence=c.fence)


def crba(robot: Robot, q):
    """Joint-space mass matrix by the composite rigid-body algorithm, shape (n, n), symmetric.

    Raises like :func:`rnea` for NaN/inf ``q`` and a robot without inertial parameters."""
    has_inertia("crba", robot)
    return _crba(robot, q, "crba")


def _crba(robot: Robot, q, fn, check=True):
    """:func:`crba` without the inertia check (see :func:`_rnea`)."""
    if check:
        (q,) = _checked(fn, robot, q=q)
    if cp.coupled(robot):  # M = G^T M_tree G
        G = cp.matrix(robot)
        return G.T @ _crba(cp.tree(robot), cp.positions(robot, q), fn, check=False) @ G
    n = robot.nq
    c = consts(robot)
    ls = walk(robot, c, q)
    # composite inertias kept as 10 parameters: the child-to-parent step is linear in them
    Ic = list(c.inertia)
    for i in reversed(range(n)):
        par = robot.parents[i]
        if par >= 0:
            (Ic[par],) = s.barrier(Ic[par] + _inertia_to_parent(robot, c, i, ls, Ic[i]), fence=c.fence)
    M = [[0.0] * n for _ in range(n)]
    for i in range(n):
        sw, sv = motion(robot, c, i)
        Fn, Ff = Ic[i].apply(sw, sv)
        M[i][i] = s.add(s.dot(sw, Fn), s.dot(sv, Ff))
        j = i
        while robot.parents[j] >= 0:
            Fn, Ff = s.barrier(*s.force_to_parent(ls.R[j], ls.p[j], Fn, Ff), fence=c.fence)
            j = robot.parents[j]
            sw, sv = motion(robot, c, j)
            M[i][j] = M[j][i] = s.add(s.dot(sw, Fn), s.dot(sv, Ff))
    dt = _dtype()
    # one flat stack then a reshape: nested row stacks cost an extra interleaving pass per level
    return s.stack([x for row in M for x in row], dt).reshape(n, n)


# ---- ABA: 6-vectors and 6x6 matrices as lists of scalars ((w, v) ordering) ----------------
# The articulated inertias are symmetric: only the 21 upper-triangle entries are computed, and
# the lower triangle holds the same scalars (mirrored references, see _sym6).


def _v6(w, v):
    return list(w) + list(v)


def _mv6(A, x):
    return [s.sum_(*(s.mul(a, b) for a, b in zip(row, x))) for row in A]


def _sym6(entry, n=6):
    """The symmetric n x n list whose upper-triangle entry (r, k), r <= k, is ``entry(r, k)``."""
    M = [[None] * n for _ in range(n)]
    for r in range(n):
        for k in range(r, n):
            M[r][k] = M[k][r] = entry(r, k)
    return M


def _I6(I: s.Inertia):
    H = s.skew(I.h)
    rows = [list(I.I.r[i]) + list(H.r[i]) for i in range(3)]
    rows += [[s.mul(-1.0, x) for x in H.r[i]] + [I.m if j == i else 0.0 for j in range(3)] for i in range(3)]
    return rows


def _bias_force(I: s.Inertia, w: s.V3, v: s.V3):
    """v x* (I v) for the body velocity (w, v). With a known mass m > 0 at the centre c = h / m,
    by Newton-Euler at the centre: f = m g, n = w x (I_c w) + h x g, g = w x (v + w x c)
    (about 60 operations against 72 for the cross products of the momentum)."""
    m = I.m
    known = isinstance(m, float) and m > 0 and all(isinstance(x, float) for x in (*I.h, *(y for r in I.I.r for y in r)))
    if not known or all(s._is(x, 0.0) for x in v):  # (v = 0, e.g. the first bodies: the momentum's form folds further)
        mw, mv = I.apply(w, v)
        return s.cross_force(w, v, mw, mv)
    h = I.h
    c = s.V3(*(x / m for x in h))
    # I_c = I_o - m ((c.c) 1 - c c^T) = I_o - ((h.c) 1 - h c^T), from known numbers
    hc = sum(a * b for a, b in zip(h, c))
    Ic = s.M33(*(s.V3(*(I.I.r[r][k] - ((hc if r == k else 0.0) - h[r] * c[k]) for k in range(3))) for r in range(3)))
    g = s.cross(w, v + s.cross(w, c))
    return s.cross(w, Ic.mv(w)) + s.cross(h, g), g.scale(m)


def _unit_axis(S):
    """k when the 6-vector S is +-e_k in trace-time floats (a joint about or along a body axis),
    else None."""
    nz = [k for k, x in enumerate(S) if not s._is(x, 0.0)]
    if len(nz) == 1 and (s._is(S[nz[0]], 1.0) or s._is(S[nz[0]], -1.0)):
        return nz[0]
    return None


def _articulated(IA, U, Dinv, k):
    """IA - U U^T / D (symmetric), with row and column k exact zeros when the joint's S = +-e_k."""
    UD = [s.mul(x, Dinv) for x in U]
    return _sym6(lambda r, j: 0.0 if k in (r, j) else s.sub(IA[r][j], s.mul(UD[r], U[j])))


def _sym_add(IA, X):
    """IA + X for symmetric IA (scalars) and X ((sign, value) entries, see :func:`_comb`)."""
    return _sym6(lambda r, j: _value(_comb([(1.0, 1.0, IA[r][j]), (1.0, *X[r][j])])))


def _signed_permutation(R: s.M33):
    """[(k, sign)] per row when the known rotation R is a signed permutation (R[i][k_i] = sign_i,
    the row's only nonzero entry): axes swapped and flipped, as URDF rpy of multiples of pi/2
    and DH twists of 0 and +-pi/2 give; else None."""
    out = []
    for row in R.r:
        nz = [(k, x) for k, x in enumerate(row) if not s._is(x, 0.0)]
        if len(nz) != 1 or not (s._is(nz[0][1], 1.0) or s._is(nz[0][1], -1.0)):
            return None
        out.append(nz[0])
    return out


def _z_rotation(robot, c, i, cs):
    """(signed permutation of the placement, cos, sin) when body i sits at R = Rpl Rz(+-q_i) with
    Rpl a signed permutation (see :func:`_signed_permutation`), else None."""
    perm = _signed_permutation(c.Rpl[i])
    rz = None if perm is None else _z_cos_sin(robot, c, i, cs)
    return None if rz is None else (perm, *rz)


def _rotate_z(M, c, sn, cs, ss, sym):
    """Rz M Rz^T for a 3x3 M, Rz the rotation about z with cosine c and sine sn (cs = c sn,
    ss = sn^2). The upper-left 2x2 block by the double-angle form: with d = M00 - M11 and
    e = M01 + M10, M00 -= t, M11 += t with t = ss d + cs e, and both off-diagonal entries += cs d - ss e
    (its trace and antisymmetric part are invariant); the third row and column as plane rotations."""
    a, b, e, d = M[0][0], M[0][1], M[1][0], M[1][1]
    dl, sg = s.sub(a, d), s.add(b, e)
    t = s.add(s.mul(ss, dl), s.mul(cs, sg))
    v = s.sub(s.mul(cs, dl), s.mul(ss, sg))
    b2 = s.add(b, v)
    e2 = b2 if sym else s.add(e, v)
    rot = lambda x, y: (s.sub(s.mul(c, x), s.mul(sn, y)), s.add(s.mul(sn, x), s.mul(c, y)))
    col = rot(M[0][2], M[1][2])
    row = col if sym else rot(M[2][0], M[2][1])
    return [[s.sub(a, t), b2, col[0]], [e2, s.add(d, t), col[1]], [row[0], row[1], M[2][2]]]


def _value(e):
    """The scalar of a (sign, value) entry."""
    return e[1] if e[0] == 1.0 else s.mul(-1.0, e[1])


def _comb(terms):
    """sum of k g v over terms (k, g, v): k a scalar, g = +-1.0, v a scalar; returned as (sign,
    value), a sum of negative terms only as (-1.0, its negation), so that signs the signed
    permutations bring pass to the next consumer instead of costing a negation each."""
    const, pos, neg = 0.0, [], []
    for k, g, v in terms:
        if s._is(k, 0.0) or s._is(v, 0.0):
            continue
        if isinstance(k, float):
            a = k * g
        else:
            a, v = g, s.mul(k, v)
        if isinstance(v, float):
            const += a * v
        elif a > 0:
            pos.append(s.mul(a, v))
        else:
            neg.append(s.mul(-a, v))
    if not pos and neg and const == 0.0:
        return -1.0, s.sum_(*neg)
    out = s.add(s.sum_(*pos), const)
    for x in neg:
        out = s.sub(out, x)
    return 1.0, out


def _congruence(R: s.M33, p: s.V3, Ia, rz=None):
    """X^T Ia X for symmetric Ia and the motion transform X = [[R^T, 0], [-R^T [p]x, R^T]] of a
    body at (R, p) in its parent, in 3x3 blocks, as (sign, value) entries (see :func:`_comb`):
    with Ia = [[A, B], [B^T, C]], rotate each block (A1 = R A R^T, ...), then shift:
    [[A1 + P B1^T - B2 P, B2], [B2^T, C1]], B2 = B1 + P C1, P = [p]x (p is a trace-time
    constant for a revolute joint). Two dense 6x6 products cost about 2.5x the operations.
    ``rz``: :func:`_z_rotation`'s (permutation, cos, sin): R = Rpl Rz(q) is applied as Rz in the
    double-angle form, then Rpl as a relabelling with signs."""
    blk = lambda r0, c0: [[Ia[r0 + r][c0 + c] for c in range(3)] for r in range(3)]
    A, B, C = blk(0, 0), blk(0, 3), blk(3, 3)
    if rz is None:
        Rr = [list(row) for row in R.r]

        def rotate(M, sym):  # R M R^T (upper triangle mirrored when sym)
            RM = [[s.signed_sum((Rr[i][k], M[k][j]) for k in range(3)) for j in range(3)] for i in range(3)]
            e = lambda i, j: (1.0, s.signed_sum((RM[i][k], Rr[j][k]) for k in range(3)))
            return _sym6(e, 3) if sym else [[e(i, j) for j in range(3)] for i in range(3)]
    else:
        perm, c, sn = rz
        cs, ss = s.mul(c, sn), s.mul(sn, sn)

        def rotate(M, sym):
            M1 = _rotate_z(M, c, sn, cs, ss, sym)
            return [[(gi * gj, M1[ki][kj]) for kj, gj in perm] for ki, gi in perm]
    A1, B1, C1 = rotate(A, True), rotate(B, False), rotate(C, True)
    P = [list(row) for row in s.skew(p).r]
    B2 = [[_comb([(1.0, *B1[i][j])] + [(P[i][k], *C1[k][j]) for k in range(3)]) for j in range(3)] for i in range(3)]
    # -P[k][j] = P[j][k]
    A2 = _sym6(lambda i, j: _comb([(1.0, *A1[i][j])] + [(P[i][k], *B1[j][k]) for k in range(3)]
                                  + [(P[j][k], *B2[i][k]) for k in range(3)]), 3)
    return [A2[r] + B2[r] for r in range(3)] + [[B2[c][r] for c in range(3)] + C1[r] for r in range(3)]


def _barrier6(fence, *blocks):
    """:func:`_scalar.barrier` for nested lists of scalars (6-vectors, 6x6 matrices); a scalar held
    twice (the mirrored half of a symmetric matrix) passes once and stays shared."""
    flat, seen = [], {}

    def put(x):
        if isinstance(x, list):
            return [put(y) for y in x]
        if isinstance(x, float) or x is None:
            return ("c", x)
        if id(x) not in seen:
            seen[id(x)] = len(flat)
            flat.append(x)
        return seen[id(x)]

    tags = [put(b) for b in blocks]
    vals = s.barrier(*flat, fence=fence)

    def get(t):
        if isinstance(t, list):
            return [get(y) for y in t]
        return t[1] if isinstance(t, tuple) else vals[t]

    return [get(t) for t in tags]


def aba(robot: Robot, q, qd, tau, f_ext=None):
    """Forward dynamics by the articulated-body algorithm: joint accelerations (n,).

    Raises :class:`jflex.DataError` for NaN/inf arguments and :class:`jflex.ParameterError` when a
    joint moves no inertia (the mass matrix is singular), naming the joint; inside ``jit`` with the
    robot traced both are run-time errors with the same messages.

    Forward-mode derivatives in ``q``, ``qd``, ``tau`` come from :func:`jflex.aba_derivatives` (a
    custom JVP, as :func:`rnea`'s).

    A robot with coupled (mimic) joints is solved by the mass matrix and a Cholesky factorisation
    (``method="crba"`` of :func:`forward_dynamics`): the recursion has no coordinate per body."""
    if cp.coupled(robot):
        return _fd_crba(robot, q, qd, tau, f_ext, "aba")
    moving_inertia("aba", robot)
    q, qd, tau, f_ext = _checked("aba", robot, q=q, qd=qd, tau=tau, f_ext=f_ext)
    if not _concrete(robot):
        return _aba_core(robot, q, qd, tau, f_ext, "aba")
    # the singular-inertia check leaves the custom JVP as a value and is made outside it, where a
    # batch program can return it as a flag (jflex.batched) instead of calling back into Python
    out, singular = _aba_analytic(robot, q, qd, tau, f_ext)
    return guard(out, [singular > 0], [_SINGULAR.format(fn="aba")])


_aba_analytic = _state_derivative(lambda *a: _aba_core(*a, "aba", flag=True), aba_derivatives)
_SINGULAR = ("{fn}: a joint moves no inertia (articulated inertia <= 0 about its axis): the mass matrix is singular; "
             "check robot.inertia")


def _aba(robot: Robot, q, qd, tau, f_ext, fn):
    if cp.coupled(robot):
        return _fd_crba(robot, q, qd, tau, f_ext, fn)
    moving_inertia(fn, robot)
    q, qd, tau, f_ext = _checked(fn, robot, q=q, qd=qd, tau=tau, f_ext=f_ext)
    return _aba_core(robot, q, qd, tau, f_ext, fn)


def _aba_core(robot: Robot, q, qd, tau, f_ext, fn, flag=False):
    """ABA's accelerations; with ``flag``, ``(accelerations, singular)`` where ``singular`` (1.0 or
    0.0) says whether some articulated inertia came out <= 0, checked by the caller."""
    n = robot.nq
    c = consts(robot)
    ls = walk(robot, c, q, qd)
    S = [_v6(*motion(robot, c, i)) for i in range(n)]
    IA, pA, cc = [], [], []
    for i in range(n):
        I = c.inertia[i]
        IA.append(_I6(I))
        bw, bv = _bias_force(I, ls.w[i], ls.v[i])
        if f_ext is not None:
            bw = bw - s.V3(f_ext[i, 3], f_ext[i, 4], f_ext[i, 5])
            bv = bv - s.V3(f_ext[i, 0], f_ext[i, 1], f_ext[i, 2])
        pA.append(_v6(bw, bv))
        sw, sv = motion(robot, c, i)
        cw, cv = s.cross_motion(ls.w[i], ls.v[i], sw.scale(qd[i]), sv.scale(qd[i]))
        cc.append(_v6(cw, cv))
    U, D, Dinv, u = [None] * n, [None] * n, [None] * n, [None] * n
    for i in reversed(range(n)):
        U[i] = _mv6(IA[i], S[i])
        D[i] = s.sum_(*(s.mul(a, b) for a, b in zip(S[i], U[i])))
        u[i] = s.sub(tau[i], s.sum_(*(s.mul(a, b) for a, b in zip(S[i], pA[i]))))
        if isinstance(D[i], float) and not D[i] > 0:
            raise ParameterError(
                f"{fn}: joint '{robot.joint_names[i]}' moves no inertia (articulated inertia {D[i]} about its axis): "
                "the mass matrix is singular; give the links it carries inertial parameters (robot.inertia)"
            )
        Dinv[i] = 1.0 / D[i]
        par = robot.parents[i]
        if par >= 0:
            # Ia = IA - U U^T / D, symmetric; Ia S = 0, so for S = +-e_k its row and column k are
            # exactly zero (set so, which folds them out of what follows)
            Ia = _articulated(IA[i], U[i], Dinv[i], _unit_axis(S[i]))
            uD = s.mul(u[i], Dinv[i])
            Iac = _mv6(Ia, cc[i])
            pa = [s.sum_(pA[i][r], Iac[r], s.mul(U[i][r], uD)) for r in range(6)]
            Ia, pa = _barrier6(c.fence, Ia, pa)
            XtIaX = _congruence(ls.R[i], ls.p[i], Ia, _z_rotation(robot, c, i, ls.cs[i]))
            IA[par] = _sym_add(IA[par], XtIaX)
            fw, fv = s.force_to_parent(ls.R[i], ls.p[i], s.V3(*pa[:3]), s.V3(*pa[3:]))
            pA[par] = [s.add(a, b) for a, b in zip(pA[par], _v6(fw, fv))]
            IA[par], pA[par] = _barrier6(c.fence, IA[par], pA[par])
    a0 = (s.ZERO, -c.gravity)
    a = [None] * n
    qdd = [None] * n
    for i in range(n):
        par = robot.parents[i]
        aw, av = a0 if par < 0 else (s.V3(*a[par][:3]), s.V3(*a[par][3:]))
        ap = [s.add(x, y) for x, y in zip(_v6(*s.motion_to_child(ls.R[i], ls.p[i], aw, av)), cc[i])]
        qdd[i] = s.mul(s.sub(u[i], s.sum_(*(s.mul(x, y) for x, y in zip(U[i], ap)))), Dinv[i])
        a[i] = [s.add(x, s.mul(y, qdd[i])) for x, y in zip(ap, S[i])]
        a[i], (qdd[i],) = _barrier6(c.fence, a[i], [qdd[i]])
    out = s.stack(qdd, _dtype())
    Dt = [d for d in D if not isinstance(d, float)]
    # singular only for some postures or a traced robot: checked at run time
    singular = jnp.any(jnp.stack(Dt) <= 0) if Dt else jnp.asarray(False)
    if flag:
        return out, singular.astype(out.dtype)
    return guard(out, [singular], [_SINGULAR.format(fn=fn)]) if Dt else out


def forward_dynamics(robot: Robot, q, qd, tau, f_ext=None, method: str = "aba"):
    """Joint accelerations (n,) from torques: ``qdd = M^-1 (tau - h)``.

    ``method="aba"`` (default: the articulated-body algorithm, O(n); for the 7-joint Panda in
    ``benchmarks/bench_dynamics.py`` it was faster at batch 1e3, 1.04 against 1.35 us, and even
    at 1e5) or ``"crba"`` (mass matrix and Cholesky solve; what either gives for a robot with
    coupled joints).
    """
    if not isinstance(method, str) or method not in ("aba", "crba"):
        raise ParameterError(f"forward_dynamics: method must be 'aba' or 'crba', got {method!r}")
    if method == "aba":
        return _aba(robot, q, qd, tau, f_ext, "forward_dynamics")
    return _fd_crba(robot, q, qd, tau, f_ext, "forward_dynamics (method='crba')")


def _fd_crba(robot: Robot, q, qd, tau, f_ext, fn):
    """``qdd = M^-1 (tau - h)`` by the mass matrix and a Cholesky solve."""
    if cp.coupled(robot):  # a joint of the tree moving no inertia may still leave G^T M G regular
        has_inertia(fn, robot)
    else:
        moving_inertia(fn, robot)
    q, qd, tau, f_ext = _checked(fn, robot, q=q, qd=qd, tau=tau, f_ext=f_ext)
    M = _crba(robot, q, fn, check=False)
    h = _rnea(robot, q, qd, jnp.zeros_like(qd), f_ext, fn, check=False)
    L = jnp.linalg.cholesky(M)
    out = jax.scipy.linalg.cho_solve((L, True), tau - h)
    # a matrix that is not positive definite leaves NaN on L's diagonal from the failing pivot on
    return guard(out, [~jnp.all(jnp.isfinite(jnp.diagonal(L)))], [
        f"{fn}: the mass matrix is not positive definite (a joint moves no inertia?); check robot.inertia"])


_UNIT_PARAMS = [s.Inertia.of([1.0 if j == k else 0.0 for j in range(10)]) for k in range(10)]


def regressor(robot: Robot, q, qd, qdd):
    """Joint-torque regressor Y (nq, 10 n) with ``rnea(q, qd, qdd) == Y @ robot.inertia.ravel()``
    (``n`` links, one per joint of the tree; ``nq = n`` unless joints are coupled).

    Parameters per link in Pinocchio's order ``[m, m c_x, m c_y, m c_z, I_xx, I_xy, I_yy, I_xz,
    I_yz, I_zz]``, inertia about the body-frame origin.
    """
    q, qd, qdd = _checked("regressor", robot, q=q, qd=qd, qdd=qdd)
    if cp.coupled(robot):  # Y = G^T Y_tree
        full = regressor(cp.tree(robot), cp.positions(robot, q), cp.rates(robot, qd), cp.rates(robot, qdd))
        return cp.project(robot, full)
    n = robot.nq
    c = consts(robot, inertia=False)
    ls = walk(robot, c, q, qd, qdd)
    Y = [[0.0] * (10 * n) for _ in range(n)]
    for j in range(n):
        for k, E in enumerate(_UNIT_PARAMS):
            # the body force is linear in the parameters: column k is the force of unit parameter k
            hw, hv = E.apply(ls.aw[j], ls.av[j])
            mw, mv = E.apply(ls.w[j], ls.v[j])
            cw, cv = s.cross_force(ls.w[j], ls.v[j], mw, mv)
            Fn, Ff = hw + cw, hv + cv
            i = j
            while True:
                sw, sv = motion(robot, c, i)
                Y[i][10 * j + k] = s.add(s.dot(sw, Fn), s.dot(sv, Ff))
                par = robot.parents[i]
                if par < 0:
                    break
                Fn, Ff = s.force_to_parent(ls.R[i], ls.p[i], Fn, Ff)
                i = par
    dt = _dtype()
    return jnp.stack([s.stack(row, dt) for row in Y])


def kinetic_energy(robot: Robot, q, qd):
    """Kinetic energy [J]: sum over bodies of v^T I v / 2."""
    q, qd = _checked("kinetic_energy", robot, q=q, qd=qd)
    if cp.coupled(robot):
        robot, q, qd = cp.tree(robot), cp.positions(robot, q), cp.rates(robot, qd)
    c = consts(robot)
    ls = walk(robot, c, q, qd)
    T = 0.0
    for i in range(robot.nq):
        mw, mv = c.inertia[i].apply(ls.w[i], ls.v[i])
        T = s.add(T, s.mul(0.5, s.add(s.dot(ls.w[i], mw), s.dot(ls.v[i], mv))))
    return jnp.asarray(T, dtype=_dtype())


def potential_energy(robot: Robot, q):
    """Gravitational potential energy [J] relative to the base origin: -sum m g . c."""
    (q,) = _checked("potential_energy", robot, q=q)
    if cp.coupled(robot):
        robot, q = cp.tree(robot), cp.positions(robot, q)
    c = consts(robot)
    ls = walk(robot, c, q, world=True)
    V = 0.0
    for i in range(robot.nq):
        I = c.inertia[i]
        V = s.sub(V, s.dot(c.gravity, ls.op[i].scale(I.m) + ls.oR[i].mv(I.h)))
    return jnp.asarray(V, dtype=_dtype())
