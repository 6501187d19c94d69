"""Rigid-body motion of a closed-loop planar linkage from its loop-closure equations.

A linkage is described by a residual ``Phi(q, phi, args) = 0`` (as many equations as unknown
coordinates ``q``) with ``phi`` the crank angle. Positions come from Newton's method
(optimistix); velocities and accelerations with respect to the crank angle from the
differentiated constraints,

$$ \\Phi_q q' = -\\Phi_\\phi, \\qquad \\Phi_q q'' = -\\frac{d^2}{ds^2}\\Phi(q + s q', \\phi + s)\\big|_{s=0}, $$

so that for a crank turning at constant ``omega``: ``qdot = omega q'``, ``qddot = omega^2 q''``.
"""

from __future__ import annotations

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, ArrayLike, Float

from .._errors import SolverError


class LinkageMotion(eqx.Module):
    """Coordinates of a linkage and their first two derivatives with respect to the crank angle."""

    phi: Float[Array, "..."]
    """Crank angle, rad."""
    q: Float[Array, "... m"]
    """Coordinates solving the loop-closure equations."""
    dq: Float[Array, "... m"]
    """``dq/dphi``."""
    ddq: Float[Array, "... m"]
    """``d^2 q/dphi^2``."""


def solve_loop_closure(
    residual: Callable,
    q0: Float[ArrayLike, " m"],
    phi: ArrayLike,
    args=None,
    *,
    solver: optx.AbstractRootFinder | None = None,
    max_steps: int = 50,
    throw: bool = True,
) -> Float[Array, " m"]:
    """Positions ``q`` with ``residual(q, phi, args) = 0``, by Newton's method from ``q0``.

    **Arguments:**

    - `residual`: ``(q (m,), phi (), args) -> (m,)``, lengths in m, angles in rad.
    - `q0`: initial guess (m,): it selects the assembly branch.
    - `phi`: crank angle, rad.
    - `solver`: an optimistix root finder; default ``optx.Newton(rtol=1e-13, atol=1e-13)``.

    **Returns:** ``q``, (m,).
    """
    solver = optx.Newton(rtol=1e-13, atol=1e-13) if solver is None else solver
    sol = optx.root_find(
        lambda q, a: residual(q, phi, a), solver, jnp.asarray(q0, float), args, max_steps=max_steps, throw=throw
    )
    return sol.value


def motion_derivatives(residual: Callable, q: ArrayLike, phi: ArrayLike, args=None) -> tuple[Array, Array]:
    """``(q', q'')``: first and second derivatives of the loop-closure solution in the crank angle.

    **Arguments:** `residual` as in :func:`solve_loop_closure`; `q` (m,) a solution at `phi` (rad).

    **Returns:** ``(dq/dphi, d^2q/dphi^2)``, each (m,).
    """
    q = jnp.asarray(q, float)
    phi = jnp.asarray(phi, float)
    f = lambda qq, pp: residual(qq, pp, args)
    Jq = jax.jacfwd(f, argnums=0)(q, phi)
    Jp = jax.jacfwd(f, argnums=1)(q, phi)
    dq = -jnp.linalg.solve(Jq, Jp)
    g = lambda s: f(q + s * dq, phi + s)
    gamma = jax.jvp(lambda s: jax.jvp(g, (s,), (jnp.ones_like(s),))[1], (jnp.zeros(()),), (jnp.ones(()),))[1]
    ddq = -jnp.linalg.solve(Jq, gamma)
    return dq, ddq


def linkage_motion(
    residual: Callable, q0: Float[ArrayLike, " m"], phis: Float[ArrayLike, " n"], args=None, *, throw: bool = True
) -> LinkageMotion:
    """Solve the loop closure over a sequence of crank angles by continuation.

    Each solve starts from the previous solution, so the linkage stays on the branch that ``q0``
    selects. A Newton failure raises :class:`jflex.SolverError` naming the crank angle.

    **Arguments:**

    - `residual`: as in :func:`solve_loop_closure`.
    - `q0`: guess at ``phis[0]``, (m,).
    - `phis`: crank angles in order, rad, (n,).

    **Returns:** :class:`LinkageMotion` with leading axis n.
    """
    phis = jnp.asarray(phis, float)
    q, dq, ddq, ok = _continuation(residual, jnp.asarray(q0, float), phis, args)
    if throw and not bool(jnp.all(ok)):
        bad = int(jnp.argmin(ok))
        raise SolverError(
            f"linkage_motion: Newton did not converge at crank angle {float(phis[bad]):.6g} rad; "
            "the linkage may not assemble there (check the dimensions) or the step in phi is too large"
        )
    return LinkageMotion(phi=phis, q=q, dq=dq, ddq=ddq)


@eqx.filter_jit
def _continuation(residual, q0, phis, args):
    def step(q, phi):
        sol = optx.root_find(
            lambda qq, a: residual(qq, phi, a), optx.Newton(rtol=1e-13, atol=1e-13), q, args,
            max_steps=50, throw=False,
        )
        qn = sol.value
        ok = sol.result == optx.RESULTS.successful
        dq, ddq = motion_derivatives(residual, qn, phi, args)
        return qn, (qn, dq, ddq, ok)

    _, out = jax.lax.scan(step, q0, phis)
    return out


def point_motion(points: Callable, motion: LinkageMotion, args=None) -> tuple[Array, Array, Array]:
    """Positions of points and their first two crank-angle derivatives along a :class:`LinkageMotion`.

    **Arguments:**

    - `points`: ``(q, phi, args) -> (p, 2)`` positions of points fixed on the links, m.
    - `motion`: the linkage motion (leading axis n).

    **Returns:** ``(P, P', P'')``, each (n, p, 2); times ``omega`` and ``omega^2`` give velocity and acceleration.
    """
    return _point_motion(points, motion, args)


@eqx.filter_jit
def _point_motion(points, motion, args):
    def one(q, dq, ddq, phi):
        # Along the exact path q(phi + s) = q + s q' + s^2/2 q'' + O(s^3), the second s-derivative is exact.
        h = lambda s: points(q + s * dq + 0.5 * s * s * ddq, phi + s, args)
        z = jnp.zeros(())
        o = jnp.ones(())
        p, dp = jax.jvp(h, (z,), (o,))
        ddp = jax.jvp(lambda s: jax.jvp(h, (s,), (o,))[1], (z,), (o,))[1]
        return p, dp, ddp

    return jax.vmap(one)(motion.q, motion.dq, motion.ddq, motion.phi)
