"""Array-valued rotation and inertia helpers used at the edges (builders, outputs).

The rigid-body kernels themselves use the scalarised algebra of ``_scalar``.
"""

from __future__ import annotations

import jax.numpy as jnp


def skew(a, xp=jnp):
    """(3,) -> (3, 3) with skew(a) @ b == cross(a, b). ``xp=numpy`` computes on the host (no
    JAX program: a model being loaded)."""
    z = xp.zeros_like(a[0])
    return xp.array([[z, -a[2], a[1]], [a[2], z, -a[0]], [-a[1], a[0], z]])


def rot_axis_angle(axis, angle, xp=jnp):
    """Rotation matrix about a unit ``axis`` (3,) by ``angle`` [rad] (Rodrigues); ``xp`` as in
    :func:`skew`."""
    K = skew(axis, xp)
    return xp.eye(3) + xp.sin(angle) * K + (1.0 - xp.cos(angle)) * (K @ K)


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


def homogeneous(R, p):
    """(3, 3), (3,) -> (4, 4)."""
    top = jnp.concatenate([R, p[:, None]], axis=1)
    return jnp.concatenate([top, jnp.array([[0.0, 0.0, 0.0, 1.0]], dtype=top.dtype)], axis=0)


def inertia_matrix3(pi, xp=jnp):
    """Rotational inertia about the frame origin from the 10 parameters (Pinocchio order); ``xp``
    as in :func:`skew`."""
    return xp.array([[pi[4], pi[5], pi[7]], [pi[5], pi[6], pi[8]], [pi[7], pi[8], pi[9]]])


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
