"""Equations of motion from a Lagrangian by automatic differentiation.

For ``L = T(x, xd) - V(x)`` with ``T`` quadratic in ``xd``: ``M(x)`` is the Hessian of ``T`` in
the velocities, and the Coriolis, centrifugal and potential terms
``h = d/dt(dT/dxd)|_{xdd=0} - dT/dx + dV/dx`` come from one jvp of ``dT/dxd`` along ``xd``.
:class:`jflex.Model` assembles its effects this way; these functions expose the same
construction for any energy pair (and give an independent check of RNEA / CRBA).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def lagrangian_mass_matrix(T, x):
    """``M(x) = d^2 T / dxd^2`` (nx, nx) for a kinetic energy ``T(x, xd)`` [J]."""
    x = jnp.asarray(x)
    return jax.hessian(lambda v: T(x, v))(jnp.zeros_like(x))


def lagrangian_bias(T, V, x, xd):
    """``h(x, xd)`` (nx,): everything in Lagrange's equations but ``M xdd``,
    ``M xdd + h = Q``."""
    x, xd = jnp.asarray(x), jnp.asarray(xd)
    dT_dxd = lambda x_: jax.grad(lambda v: T(x_, v))(xd)
    _, dtdt = jax.jvp(dT_dxd, (x,), (xd,))
    return dtdt + jax.grad(lambda x_: V(x_) - T(x_, xd))(x)


def lagrangian_forward_dynamics(T, V, x, xd, Q):
    """``xdd`` (nx,) solving ``M(x) xdd + h(x, xd) = Q``."""
    M = lagrangian_mass_matrix(T, x)
    return jnp.linalg.solve(M, Q - lagrangian_bias(T, V, x, xd))
