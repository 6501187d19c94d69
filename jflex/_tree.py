"""The one tree traversal every algorithm reuses.

``walk`` goes from the base to the leaves computing each body's placement and, when asked, its
spatial velocity and acceleration; ``accumulate`` goes back adding spatial forces into parents;
``support`` lists a body's ancestors. Loops are Python loops over the static topology: they
unroll into one straight-line program per robot. The kernels work on the scalarised algebra of
``_scalar`` (see there why); ``forward_pass`` returns the same quantities as arrays for code
that wants them.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import _scalar as s
from ._robot import PRISMATIC, Robot
from ._spatial import rot_axis_angle
from ._trig import cos_sin


class LinkStates(NamedTuple):
    """Per-body quantities; lists of length n (None where not asked). In ``walk`` the entries are
    :class:`_scalar.V3`/:class:`_scalar.M33`, in ``forward_pass`` arrays."""

    R: list  # body axes in parent axes
    p: list  # body origin in parent frame
    oR: list | None  # body axes in base axes
    op: list | None  # body origin in base frame
    w: list | None  # angular velocity, body axes
    v: list | None  # origin velocity, body axes
    aw: list | None  # spatial acceleration (angular), body axes
    av: list | None  # spatial acceleration (linear), body axes
    cs: list | None = None  # (cos q_i, sin q_i) per revolute joint, None for a prismatic one


def host(a):
    """Robot leaves as NumPy when known at trace time (so their entries fold into constants)."""
    return a if isinstance(a, jax.core.Tracer) else np.asarray(a)


class RobotConsts(NamedTuple):
    """A robot's per-body numbers in scalarised form, made once per trace."""

    Rpl: list
    ppl: list
    axis: list
    inertia: list
    gravity: s.V3
    fence: object = None  # run-time boolean for _scalar.barrier when the robot is traced, else None


def _snap(a):
    """Rotation entries within 1e-14 of 0 or +-1 (cos(pi/2) = 6e-17 from a URDF's rpy) made exact,
    so trace-time folding drops them; a change below float64 resolution at unit scale."""
    if isinstance(a, jax.core.Tracer):
        return a
    a = np.array(a, dtype=float)
    a[np.abs(a) < 1e-14] = 0.0
    one = np.abs(np.abs(a) - 1.0) < 1e-14
    a[one] = np.sign(a[one])
    return a


def _fence(robot: Robot):
    """With robot leaves traced (``jax.jit(jflex.rnea)(robot, ...)``) nothing folds and XLA:CPU's
    fusion would recompute each body's cone in every consumer (35-42 s to compile the Panda's
    ABA): the barriers become conditionals on this run-time predicate (a NaN robot, so never
    taken for a valid one; unbatched under vmap). None for a robot known at trace time."""
    leaves = [a for a in (robot.placement_R, robot.placement_p, robot.axis, robot.inertia, robot.gravity)
              if isinstance(a, jax.core.Tracer)]
    if not leaves:
        return None
    from equinox.internal import unvmap_any

    return unvmap_any(jnp.isnan(jnp.sum(leaves[0])))


def consts(robot: Robot, inertia=True) -> RobotConsts:
    R, p, ax = _snap(host(robot.placement_R)), host(robot.placement_p), _snap(host(robot.axis))
    n = robot.nq
    I = host(robot.inertia) if inertia else None
    return RobotConsts(
        [s.M33.of(R[i]) for i in range(n)],
        [s.V3.of(p[i]) for i in range(n)],
        [s.V3.of(ax[i]) for i in range(n)],
        [s.Inertia.of(I[i]) for i in range(n)] if inertia else None,
        s.V3.of(host(robot.gravity)),
        _fence(robot),
    )


def motion(robot: Robot, c: RobotConsts, i: int):
    """Motion subspace S_i as (s_w, s_v) in body axes (scalarised)."""
    if robot.joint_types[i] == PRISMATIC:
        return s.ZERO, c.axis[i]
    return c.axis[i], s.ZERO


def joint_cos_sin(robot: Robot, q) -> list:
    """``(cos q_i, sin q_i)`` per revolute joint (None for a prismatic one) from one evaluation of
    :func:`_trig.cos_sin` over the joints: its arithmetic appears once in the program, not once per
    joint (each copy is some forty operations for XLA to fuse and compile)."""
    rev = [i for i in range(robot.nq) if robot.joint_types[i] != PRISMATIC]
    if not rev:
        return [None] * robot.nq
    qv = q if len(rev) == robot.nq and hasattr(q, "shape") else jnp.stack([q[i] for i in rev])
    cv, sv = cos_sin(qv)
    out = [None] * robot.nq
    for k, i in enumerate(rev):
        out[i] = (cv[k], sv[k])
    return out


def transform(robot: Robot, c: RobotConsts, i: int, qi, cs=None):
    """(R, p) of body i in its parent's frame at joint value ``qi`` (scalarised); ``cs``: its
    ``(cos qi, sin qi)`` when known (:func:`joint_cos_sin`)."""
    if robot.joint_types[i] == PRISMATIC:
        return c.Rpl[i], c.ppl[i] + c.Rpl[i].mv(c.axis[i].scale(qi))
    return c.Rpl[i].mm(s.rot_axis_angle(c.axis[i], *(cs if cs is not None else cos_sin(qi)))), c.ppl[i]


def walk(robot: Robot, c: RobotConsts, q, qd=None, qdd=None, base_acc: s.V3 | None = None, world=False) -> LinkStates:
    """Forward pass. ``base_acc`` defaults to ``-gravity``: gravity enters as a fictitious upward
    acceleration of the base (Featherstone's trick), which is what RNEA wants."""
    n = robot.nq
    R, p = [None] * n, [None] * n
    oR = [None] * n if world else None
    op = [None] * n if world else None
    want_v, want_a = qd is not None, qdd is not None
    w = [None] * n if want_v else None
    v = [None] * n if want_v else None
    aw = [None] * n if want_a else None
    av = [None] * n if want_a else None
    a0 = -c.gravity if base_acc is None else base_acc
    cs = joint_cos_sin(robot, q)
    for i in range(n):
        par = robot.parents[i]
        R[i], p[i] = transform(robot, c, i, q[i], cs[i])
        if world:
            if par < 0:
                oR[i], op[i] = R[i], p[i]
            else:
                oR[i], op[i] = oR[par].mm(R[i]), op[par] + oR[par].mv(p[i])
        if not want_v:
            R[i], p[i] = s.barrier(R[i], p[i], fence=c.fence)
            continue
        sw, sv = motion(robot, c, i)
        pw, pv = (s.ZERO, s.ZERO) if par < 0 else (w[par], v[par])
        cw, cv = s.motion_to_child(R[i], p[i], pw, pv)
        w[i], v[i] = cw + sw.scale(qd[i]), cv + sv.scale(qd[i])
        if not want_a:
            R[i], p[i], w[i], v[i] = s.barrier(R[i], p[i], w[i], v[i], fence=c.fence)
            continue
        paw, pav = (s.ZERO, a0) if par < 0 else (aw[par], av[par])
        caw, cav = s.motion_to_child(R[i], p[i], paw, pav)
        bw, bv = s.cross_motion(w[i], v[i], sw.scale(qd[i]), sv.scale(qd[i]))
        aw[i], av[i] = caw + sw.scale(qdd[i]) + bw, cav + sv.scale(qdd[i]) + bv
        R[i], p[i], w[i], v[i], aw[i], av[i] = s.barrier(R[i], p[i], w[i], v[i], aw[i], av[i], fence=c.fence)
    return LinkStates(R, p, oR, op, w, v, aw, av, cs)


def accumulate(robot: Robot, ls: LinkStates, n_list: list, f_list: list, fence=None):
    """Backward pass: add each body's force (n_i, f_i) into its parent; returns composite forces
    (``fence``: :attr:`RobotConsts.fence`)."""
    n_acc, f_acc = list(n_list), list(f_list)
    for i in reversed(range(robot.nq)):
        par = robot.parents[i]
        if par >= 0:
            dn, df = s.force_to_parent(ls.R[i], ls.p[i], n_acc[i], f_acc[i])
            n_acc[par], f_acc[par] = s.barrier(n_acc[par] + dn, f_acc[par] + df, fence=fence)
    return n_acc, f_acc


def support(robot: Robot, i: int) -> list[int]:
    """Body ``i`` and its ancestors, from ``i`` down to the root (static)."""
    out = []
    while i >= 0:
        out.append(i)
        i = robot.parents[i]
    return out


# ---- array-valued views for code outside the kernels -------------------------------------


def _arr(x, dtype):
    if x is None:
        return None
    return x.array().astype(dtype) if isinstance(x, (s.V3, s.M33)) else x


def forward_pass(robot: Robot, q, qd=None, qdd=None, base_acc=None) -> LinkStates:
    """:func:`walk` with array outputs ((3, 3) rotations, (3,) vectors), world placements included;
    one entry per joint of the tree (a robot with coupled joints takes its coordinates)."""
    if robot.mimic:
        from . import _coupling as cp

        rate = lambda x: None if x is None else cp.rates(robot, x)
        robot, q, qd, qdd = cp.tree(robot), cp.positions(robot, q), rate(qd), rate(qdd)
    c = consts(robot, inertia=False)
    b = None if base_acc is None else s.V3.of(base_acc)
    ls = walk(robot, c, q, qd, qdd, b, world=True)
    dt = jnp.result_type(float)
    conv = lambda lst: None if lst is None else [_arr(x, dt) for x in lst]
    return LinkStates(*(conv(f) for f in ls))


def body_placement(robot: Robot, q, b: int):
    """World rotation (3, 3) and position (3,) of body ``b`` at the angles ``q``: the chain from the
    root to ``b`` in array algebra. Code that differentiates a placement more than once (the
    flexible link's energies: a Hessian of a JVP) traces each operation once per derivative
    level: the scalarised traversal of :func:`forward_pass` spends some seventy scalar operations
    per joint where this spends a few array ones (a rotor with one flexible link traced 7 of its
    18 s of a first simulation in it)."""
    if robot.mimic:
        ls = forward_pass(robot, q)
        return ls.oR[b], ls.op[b]
    R = p = None
    for i in reversed(support(robot, b)):
        Rp, pp = jnp.asarray(host(robot.placement_R[i])), jnp.asarray(host(robot.placement_p[i]))
        ax = jnp.asarray(host(robot.axis[i]))
        if robot.joint_types[i] == PRISMATIC:
            Ri, pi = Rp, pp + Rp @ (ax * q[i])
        else:
            Ri, pi = Rp @ rot_axis_angle(ax, q[i]), pp
        R, p = (Ri, pi) if R is None else (R @ Ri, p + R @ pi)
    return R, p


def joint_motion(robot: Robot, i: int):
    """Motion subspace S_i as arrays (s_w, s_v), body axes."""
    z = jnp.zeros(3, dtype=robot.axis.dtype)
    if robot.joint_types[i] == PRISMATIC:
        return z, robot.axis[i]
    return robot.axis[i], z


def joint_transform(robot: Robot, i: int, qi):
    """(R, p) arrays of body i in its parent's frame at joint value ``qi``."""
    c = consts(robot, inertia=False)
    R, p = transform(robot, c, i, qi)
    dt = jnp.result_type(float)
    return _arr(R, dt), _arr(p, dt)
