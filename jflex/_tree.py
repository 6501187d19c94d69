"""The one tree traversal every algorithm reuses.

``forward_pass`` walks from the base to the leaves computing each body's placement, and (when
asked) its spatial velocity and acceleration; ``backward_pass`` walks back accumulating spatial
forces into parents; ``support`` lists a body's ancestors. Loops are Python loops over the static
topology: they unroll into one straight-line XLA program per robot, which is what makes the
vmapped kernels fast on CPU.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp

from . import _spatial as sp
from ._robot import PRISMATIC, Robot


class LinkStates(NamedTuple):
    """Per-body quantities from :func:`forward_pass`; lists of length n (None where not asked)."""

    R: list  # (3,3) body axes in parent axes
    p: list  # (3,) body origin in parent frame
    oR: list  # (3,3) body axes in base axes
    op: list  # (3,) body origin in base frame
    w: list | None  # angular velocity, body axes
    v: list | None  # origin velocity, body axes
    aw: list | None  # spatial acceleration (angular), body axes
    av: list | None  # spatial acceleration (linear), body axes


def joint_motion(robot: Robot, i: int):
    """Motion subspace S_i as (s_w, s_v), body axes."""
    z = jnp.zeros(3, dtype=robot.axis.dtype)
    if robot.joint_types[i] == PRISMATIC:
        return z, robot.axis[i]
    return robot.axis[i], z


def joint_transform(robot: Robot, i: int, qi):
    """(R, p) of body i in its parent's frame at joint value ``qi``."""
    Rpl, ppl = robot.placement_R[i], robot.placement_p[i]
    if robot.joint_types[i] == PRISMATIC:
        return Rpl, ppl + sp.mv(Rpl, robot.axis[i] * qi)
    return sp.mm(Rpl, sp.rot_axis_angle(robot.axis[i], qi)), ppl


def forward_pass(robot: Robot, q, qd=None, qdd=None, base_acc=None) -> LinkStates:
    """Placements, and velocities/accelerations when ``qd``/``qdd`` are given.

    ``base_acc`` is the base's linear acceleration (3,); the default ``-gravity`` folds gravity in
    as a fictitious upward acceleration of the base (Featherstone's trick), which is what RNEA wants.
    """
    n = robot.nq
    dtype = robot.placement_p.dtype
    zero = jnp.zeros(3, dtype=dtype)
    R, p, oR, op = [None] * n, [None] * n, [None] * n, [None] * n
    want_v = qd is not None
    want_a = qdd is not None
    w = [None] * n if want_v else None
    v = [None] * n if want_v else None
    aw = [None] * n if want_a else None
    av = [None] * n if want_a else None
    a0 = -robot.gravity if base_acc is None else base_acc
    for i in range(n):
        par = robot.parents[i]
        R[i], p[i] = joint_transform(robot, i, q[i])
        if par < 0:
            oR[i], op[i] = R[i], p[i]
        else:
            oR[i], op[i] = sp.compose(oR[par], op[par], R[i], p[i])
        if not want_v:
            continue
        sw, sv = joint_motion(robot, i)
        pw, pv = (zero, zero) if par < 0 else (w[par], v[par])
        cw, cv = sp.motion_to_child(R[i], p[i], pw, pv)
        w[i], v[i] = cw + sw * qd[i], cv + sv * qd[i]
        if not want_a:
            continue
        paw, pav = (zero, a0) if par < 0 else (aw[par], av[par])
        caw, cav = sp.motion_to_child(R[i], p[i], paw, pav)
        bw, bv = sp.cross_motion(w[i], v[i], sw * qd[i], sv * qd[i])
        aw[i], av[i] = caw + sw * qdd[i] + bw, cav + sv * qdd[i] + bv
    return LinkStates(R, p, oR, op, w, v, aw, av)


def backward_pass(robot: Robot, ls: LinkStates, n_list: list, f_list: list):
    """Accumulate body forces (n_i, f_i) into parents; returns the composite forces (lists)."""
    n_acc, f_acc = list(n_list), list(f_list)
    for i in reversed(range(robot.nq)):
        par = robot.parents[i]
        if par >= 0:
            dn, df = sp.force_to_parent(ls.R[i], ls.p[i], n_acc[i], f_acc[i])
            n_acc[par] = n_acc[par] + dn
            f_acc[par] = f_acc[par] + df
    return n_acc, f_acc


def support(robot: Robot, i: int) -> list[int]:
    """Body ``i`` and its ancestors, from ``i`` down to the root (static)."""
    out = []
    while i >= 0:
        out.append(i)
        i = robot.parents[i]
    return out
