"""Planar finite elements: Euler-Bernoulli beams with axial stretch, bars, and their rotation.

Local beam DOFs are ``(u1, v1, th1, u2, v2, th2)``: axial and transverse translation and the
in-plane rotation at each node (press paper, Eq. 1: linear axial, cubic transverse field).
Global DOFs per node are ``(ux, uy, th)`` in the inertial frame.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float


def beam_local_stiffness(E: ArrayLike, A: ArrayLike, I: ArrayLike, L: ArrayLike) -> Float[Array, "6 6"]:
    """Stiffness of a uniform Euler-Bernoulli beam element with axial stretch, local axes.

    **Arguments:**

    - `E`: Young's modulus, Pa (scalar).
    - `A`: cross-section area, m^2.
    - `I`: second moment of area about the axis normal to the plane, m^4.
    - `L`: element length, m.

    **Returns:** the (6, 6) stiffness on ``(u1, v1, th1, u2, v2, th2)``, N/m, N, N m.
    """
    a = E * A / L
    b = E * I / L**3
    L2 = L * L
    z = jnp.zeros_like(a * b)
    rows = [
        [a, z, z, -a, z, z],
        [z, 12 * b, 6 * L * b, z, -12 * b, 6 * L * b],
        [z, 6 * L * b, 4 * L2 * b, z, -6 * L * b, 2 * L2 * b],
        [-a, z, z, a, z, z],
        [z, -12 * b, -6 * L * b, z, 12 * b, -6 * L * b],
        [z, 6 * L * b, 2 * L2 * b, z, -6 * L * b, 4 * L2 * b],
    ]
    return jnp.stack([jnp.stack(r) for r in rows])


def beam_local_mass(rho: ArrayLike, A: ArrayLike, L: ArrayLike) -> Float[Array, "6 6"]:
    """Consistent mass of a uniform beam element (linear axial, cubic Hermite transverse), local axes.

    **Arguments:**

    - `rho`: density, kg/m^3.
    - `A`: cross-section area, m^2.
    - `L`: element length, m.

    **Returns:** the (6, 6) consistent mass on ``(u1, v1, th1, u2, v2, th2)``.
    """
    m = rho * A * L
    a = m / 6.0
    b = m / 420.0
    L2 = L * L
    z = jnp.zeros_like(m)
    rows = [
        [2 * a, z, z, a, z, z],
        [z, 156 * b, 22 * L * b, z, 54 * b, -13 * L * b],
        [z, 22 * L * b, 4 * L2 * b, z, 13 * L * b, -3 * L2 * b],
        [a, z, z, 2 * a, z, z],
        [z, 54 * b, 13 * L * b, z, 156 * b, -22 * L * b],
        [z, -13 * L * b, -3 * L2 * b, z, -22 * L * b, 4 * L2 * b],
    ]
    return jnp.stack([jnp.stack(r) for r in rows])


def beam_rotation(angle: ArrayLike) -> Float[Array, "6 6"]:
    """Transformation ``u_local = T u_global`` of a beam element whose axis is at ``angle`` (rad)."""
    c, s = jnp.cos(angle), jnp.sin(angle)
    z, o = jnp.zeros_like(c), jnp.ones_like(c)
    R = jnp.stack([jnp.stack([c, s, z]), jnp.stack([-s, c, z]), jnp.stack([z, z, o])])
    Z = jnp.zeros((3, 3), R.dtype)
    return jnp.block([[R, Z], [Z, R]])


def beam_matrices(
    E: ArrayLike, A: ArrayLike, I: ArrayLike, rho: ArrayLike, xi: Float[ArrayLike, "2"], xj: Float[ArrayLike, "2"]
) -> tuple[Float[Array, "6 6"], Float[Array, "6 6"]]:
    """Global stiffness and consistent mass of a beam element between node positions ``xi``, ``xj``.

    **Arguments:**

    - `E, A, I, rho`: modulus (Pa), area (m^2), second moment (m^4), density (kg/m^3).
    - `xi, xj`: node positions, shape (2,), m.

    **Returns:** ``(K, M)``, each (6, 6) on ``(ux_i, uy_i, th_i, ux_j, uy_j, th_j)`` (press paper, Eqs. 8-9).
    """
    d = jnp.asarray(xj) - jnp.asarray(xi)
    L = jnp.sqrt(d @ d)
    T = beam_rotation(jnp.arctan2(d[1], d[0]))
    K = T.T @ beam_local_stiffness(E, A, I, L) @ T
    M = T.T @ beam_local_mass(rho, A, L) @ T
    return K, M


def bar_matrices(
    E: ArrayLike, A: ArrayLike, L: ArrayLike, rho: ArrayLike, angle: ArrayLike
) -> tuple[Float[Array, "4 4"], Float[Array, "4 4"]]:
    """Global stiffness and consistent mass of a two-node bar (axial stiffness only).

    The bar's axis direction and length are arguments rather than node geometry, because the
    bars that stand for a rotation joint (press paper, Sec. 2.3) join nodes that coincide: their
    length is the journal radius ``R`` and their direction the joint's load axis.

    **Arguments:**

    - `E`: (equivalent) modulus, Pa.
    - `A`: area, m^2.
    - `L`: length, m.
    - `rho`: density, kg/m^3 (0 when the joint's mass is lumped on a node, as in the press paper).
    - `angle`: direction of the axis from node i to node j, rad.

    **Returns:** ``(K, M)``, each (4, 4) on ``(ux_i, uy_i, ux_j, uy_j)``.
    """
    c, s = jnp.cos(angle), jnp.sin(angle)
    e = jnp.stack([-c, -s, c, s])
    K = (E * A / L) * jnp.outer(e, e)
    m = rho * A * L / 6.0
    M = m * jnp.kron(jnp.array([[2.0, 1.0], [1.0, 2.0]]), jnp.eye(2))
    return K, M


def bimodular_modulus(axial_force: ArrayLike, E_tension: ArrayLike, E_compression: ArrayLike) -> Array:
    """Equivalent modulus of a joint bar that differs in tension and compression (press paper, Sec. 2.3.2).

    **Arguments:**

    - `axial_force`: the bar's axial force ``F_N``, N (tension positive), any shape.
    - `E_tension, E_compression`: moduli for ``F_N >= 0`` and ``F_N < 0``, Pa.

    **Returns:** the modulus, same shape as `axial_force`.
    """
    return jnp.where(jnp.asarray(axial_force) >= 0, E_tension, E_compression)
