"""Small spatial-algebra kernels for one item (no batch dimension; ``vmap`` where called).

Spatial motion vectors are ``(w, v)``: angular velocity and the velocity of the frame origin,
both in the frame's own axes. Spatial forces are ``(n, f)``: moment about the frame origin and
force. Transforms are stored as ``(R, p)``: the child frame's axes ``R`` and origin ``p`` in the
parent frame. Working with 3-vectors rather than 6x6 matrices keeps the per-link kernels small.
"""

from __future__ import annotations

import jax.numpy as jnp


# Small products written as multiply-adds rather than ``@``: under ``vmap`` they become plain
# elementwise vector code over the batch, which XLA on CPU runs far faster than batched tiny
# dot_generals (measured in benchmarks/bench_dynamics.py).


def dot(a, b):
    """(3,) . (3,)"""
    return jnp.dot(a, b)


def cross(a, b):
    """(3,) x (3,)"""
    return jnp.cross(a, b)


def mv(A, v):
    """(k, m) @ (m,)"""
    return A @ v


def mtv(A, v):
    """A.T @ v"""
    return A.T @ v


def mm(A, B):
    """(k, m) @ (m, l)"""
    return A @ B


def skew(a):
    """(3,) -> (3, 3) with skew(a) @ b == cross(a, b)."""
    z = jnp.zeros_like(a[0])
    return jnp.array([[z, -a[2], a[1]], [a[2], z, -a[0]], [-a[1], a[0], z]])


def rot_axis_angle(axis, angle):
    """Rotation matrix about a unit ``axis`` (3,) by ``angle`` [rad] (Rodrigues)."""
    K = skew(axis)
    return jnp.eye(3) + jnp.sin(angle) * K + (1.0 - jnp.cos(angle)) * mm(K, K)


def rot_x(a):
    c, s = jnp.cos(a), jnp.sin(a)
    return jnp.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a):
    c, s = jnp.cos(a), jnp.sin(a)
    return jnp.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a):
    c, s = jnp.cos(a), jnp.sin(a)
    return jnp.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rpy_to_matrix(rpy):
    """URDF roll-pitch-yaw (fixed axes x, y, z) -> rotation matrix ``Rz(y) Ry(p) Rx(r)``."""
    return rot_z(rpy[2]) @ rot_y(rpy[1]) @ rot_x(rpy[0])


def compose(R1, p1, R2, p2):
    """(R1, p1) * (R2, p2): frame 2 given in frame 1, frame 1 given in 0 -> frame 2 in 0."""
    return mm(R1, R2), p1 + mv(R1, p2)


def homogeneous(R, p):
    """(3, 3), (3,) -> (4, 4)."""
    top = jnp.concatenate([R, p[:, None]], axis=1)
    return jnp.concatenate([top, jnp.array([[0.0, 0.0, 0.0, 1.0]], dtype=top.dtype)], axis=0)


def motion_to_child(R, p, w, v):
    """Express a parent-frame motion (w, v) in the child frame placed at (R, p)."""
    return mtv(R, w), mtv(R, v + cross(w, p))


def force_to_parent(R, p, n, f):
    """Express a child-frame force (n, f) in the parent frame."""
    fp = mv(R, f)
    return mv(R, n) + cross(p, fp), fp


def cross_motion(w, v, w2, v2):
    """Spatial motion cross product (w, v) x (w2, v2)."""
    return cross(w, w2), cross(w, v2) + cross(v, w2)


def cross_force(w, v, n, f):
    """Spatial force cross product (w, v) x* (n, f)."""
    return cross(w, n) + cross(v, f), cross(w, f)


def inertia_matrix3(pi):
    """Rotational inertia about the frame origin from the 10 parameters (Pinocchio order)."""
    return jnp.array([[pi[4], pi[5], pi[7]], [pi[5], pi[6], pi[8]], [pi[7], pi[8], pi[9]]])


def inertia_apply(pi, w, v):
    """Spatial inertia (10 parameters ``[m, h, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]``) times motion (w, v)."""
    m, h = pi[0], pi[1:4]
    return mv(inertia_matrix3(pi), w) - cross(v, h), m * v + cross(w, h)


def inertia_6x6(pi):
    """(10,) -> (6, 6) spatial inertia for the (w, v) ordering."""
    m, h = pi[0], pi[1:4]
    H = skew(h)
    top = jnp.concatenate([inertia_matrix3(pi), H], axis=1)
    bot = jnp.concatenate([-H, m * jnp.eye(3)], axis=1)
    return jnp.concatenate([top, bot], axis=0)


def motion_transform_6x6(R, p):
    """6x6 matrix mapping parent-frame motion (w, v) to the child frame at (R, p)."""
    Rt = R.T
    z = jnp.zeros((3, 3), dtype=Rt.dtype)
    return jnp.concatenate(
        [jnp.concatenate([Rt, z], axis=1), jnp.concatenate([-Rt @ skew(p), Rt], axis=1)], axis=0
    )


def transform_params_fast(pi, R, p):
    """10 parameters about a child frame at (R, p) -> about the parent frame (linear in ``pi``);
    the composite-inertia step of CRBA, without 6x6 matrices."""
    m = pi[0]
    h = mv(R, pi[1:4])
    I = mm(mm(R, inertia_matrix3(pi)), R.T)
    hp = dot(h, p)
    pp = dot(p, p)
    # parallel-axis shift of the origin by p: I' = I + 2 (h.p) 1 - h p^T - p h^T + m (|p|^2 1 - p p^T)
    D = (2.0 * hp + m * pp) * jnp.eye(3) - h[:, None] * p[None, :] - p[:, None] * h[None, :] - m * p[:, None] * p[None, :]
    Ip = I + D
    hn = h + m * p
    return jnp.stack([m, hn[0], hn[1], hn[2], Ip[0, 0], Ip[0, 1], Ip[1, 1], Ip[0, 2], Ip[1, 2], Ip[2, 2]])


def params_from_com(mass, com, inertia_com):
    """10 parameters (Pinocchio order, inertia about the frame origin) from mass, centre of mass
    (3,) and the (3, 3) inertia about the centre of mass, all in the same frame."""
    c = jnp.asarray(com)
    I_o = jnp.asarray(inertia_com) + mass * (jnp.dot(c, c) * jnp.eye(3) - jnp.outer(c, c))
    h = mass * c
    return jnp.array(
        [mass, h[0], h[1], h[2], I_o[0, 0], I_o[0, 1], I_o[1, 1], I_o[0, 2], I_o[1, 2], I_o[2, 2]]
    )


def params_to_com(pi):
    """Inverse of :func:`params_from_com`: (mass, com (3,), inertia about the com (3, 3))."""
    m = pi[0]
    c = jnp.where(m > 0, pi[1:4] / jnp.where(m > 0, m, 1.0), 0.0)
    I_c = inertia_matrix3(pi) - m * (jnp.dot(c, c) * jnp.eye(3) - jnp.outer(c, c))
    return m, c, I_c


def transform_params(pi, R, p):
    """Re-express 10 inertial parameters given in frame A in frame B, where A sits at (R, p) in B."""
    m, c, I_c = params_to_com(pi)
    return params_from_com(m, R @ c + p, R @ I_c @ R.T)
