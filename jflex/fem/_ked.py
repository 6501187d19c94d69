"""Kineto-elastodynamics (KED): elastic response of a linkage to the inertial loads of its rigid motion.

Over a crank revolution the linkage takes ``n`` poses; at pose ``i`` the elastic model has mass
``M_i``, stiffness ``K_i`` and load ``F_i = -M_i Uddot_r,i`` (press paper, Eqs. 20, 23). Within the
time unit ``[t_i, t_{i+1}]`` the system is frozen at its start pose (press paper, Sec. 3.4) and each
mode's equation (Eq. 39) is integrated exactly for a load varying linearly over the unit.
Where the paper carries each modal coordinate unchanged from one unit to the next, the state is
carried in physical coordinates here (``eta_new = Phi_new^T M_new Phi_old eta_old``), so mode
reordering or sign flips between poses do no harm. The periodic steady state (Eqs. 42-43) is
the fixed point of the one-revolution map, solved directly.
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._errors import ParameterError
from ._assembly import Modes, modes


class AbstractDamping(eqx.Module):
    """A damping law that is diagonal in the undamped modes (classical damping)."""

    @abc.abstractmethod
    def ratios(self, omega: Float[Array, " r"]) -> Float[Array, " r"]:
        """Damping ratio of each mode, given the natural angular frequencies (rad/s)."""

    def matrix(self, M: ArrayLike, K: ArrayLike) -> Float[Array, "n n"]:
        """The damping matrix ``C = M Phi diag(2 zeta w) Phi^T M``, N s/m."""
        md = modes(M, K)
        MP = jnp.asarray(M) @ md.Phi
        return MP @ jnp.diag(2.0 * self.ratios(md.omega) * md.omega) @ MP.T


class ModalDamping(AbstractDamping):
    """The same damping ratio in every mode (press paper, Eq. 35, ``zeta = 0.05``)."""

    zeta: Float[Array, ""]

    def __init__(self, zeta: ArrayLike = 0.05):
        if not 0 <= float(zeta) < 1:
            raise ParameterError(f"ModalDamping.zeta: expected 0 <= zeta < 1, got {float(zeta)}")
        self.zeta = jnp.asarray(zeta, float)

    def ratios(self, omega):
        return jnp.full_like(omega, self.zeta)


class RayleighDamping(AbstractDamping):
    """``C = alpha M + beta K`` (press paper, Eq. 33): ``zeta(w) = alpha/(2w) + beta w/2``."""

    alpha: Float[Array, ""]
    beta: Float[Array, ""]

    def __init__(self, alpha: ArrayLike, beta: ArrayLike):
        if float(alpha) < 0 or float(beta) < 0:
            raise ParameterError(f"RayleighDamping: alpha and beta must be >= 0, got {float(alpha)}, {float(beta)}")
        self.alpha = jnp.asarray(alpha, float)
        self.beta = jnp.asarray(beta, float)

    def ratios(self, omega):
        return self.alpha / (2.0 * omega) + 0.5 * self.beta * omega

    def matrix(self, M, K):
        return self.alpha * jnp.asarray(M) + self.beta * jnp.asarray(K)


def _sdof_step(omega, zeta, h):
    """Exact step of ``x'' + 2 zeta w x' + w^2 x = p0 + pdot t`` over ``h``: (2, 4) map of (x0, v0, p0, pdot).

    Written with the characteristic roots ``-zeta w +- w sqrt(zeta^2 - 1)`` so that under- and
    over-damped modes share one formula and stiff modes (``w h >> 1``) decay to the static
    solution instead of overflowing (a matrix exponential of the same system gives NaN there).
    """
    zeta = jnp.where(jnp.abs(zeta - 1.0) < 1e-6, 1.0 - 1e-6, zeta)
    root = omega * jnp.sqrt(zeta**2 - 1.0 + 0j)
    l1, l2 = -zeta * omega + root, -zeta * omega - root

    def step(y):
        x0, v0, p0, pd = y
        b = pd / omega**2
        a = p0 / omega**2 - 2.0 * zeta * pd / omega**3
        c1 = ((v0 - b) - l2 * (x0 - a)) / (l1 - l2)
        c2 = (x0 - a) - c1
        e1, e2 = jnp.exp(l1 * h), jnp.exp(l2 * h)
        x = (c1 * e1 + c2 * e2).real + a + b * h
        v = (l1 * c1 * e1 + l2 * c2 * e2).real + b
        return jnp.stack([x, v])

    return jax.jacfwd(step)(jnp.zeros(4))


class KEDResponse(eqx.Module):
    """Elastic response of a linkage over one crank revolution (or several)."""

    t: Float[Array, " n"]
    """Times of the poses, s."""
    U: Float[Array, "n N"]
    """Elastic displacement of every free DOF, m and rad."""
    V: Float[Array, "n N"]
    """Elastic velocity, m/s and rad/s."""


@eqx.filter_jit
def pose_modes(M: Float[ArrayLike, "n N N"], K: Float[ArrayLike, "n N N"], n_modes: int | None = None) -> Modes:
    """Modes at every pose: a :class:`Modes` with leading axis n (``omega`` (n, r), ``Phi`` (n, N, r))."""
    return jax.vmap(lambda m, k: modes(m, k, n_modes))(jnp.asarray(M), jnp.asarray(K))


def _modal_maps(md: Modes, M, F, damping, dt):
    """Affine maps ``z_{i+1} = A_i z_i + b_i`` of the reduced state ``z = (eta, etadot)`` (each in its pose's basis)."""
    n = M.shape[0]
    r = md.omega.shape[1]
    nxt = (jnp.arange(n) + 1) % n
    zeta = jax.vmap(damping.ratios)(md.omega)
    E = jax.vmap(jax.vmap(_sdof_step, in_axes=(0, 0, None)), in_axes=(0, 0, None))(md.omega, zeta, dt)  # (n, r, 2, 4)
    p0 = jnp.einsum("inr,in->ir", md.Phi, F)
    p1 = jnp.einsum("inr,in->ir", md.Phi, F[nxt])
    pd = (p1 - p0) / dt
    # Basis change at the end of each unit: eta_next = Phi_next^T M_next Phi_this eta.
    T = jnp.einsum("inr,inm,ims->irs", md.Phi[nxt], M[nxt], md.Phi)
    I = jnp.eye(r)
    Axx = E[..., 0, 0][:, :, None] * I
    Axv = E[..., 0, 1][:, :, None] * I
    Avx = E[..., 1, 0][:, :, None] * I
    Avv = E[..., 1, 1][:, :, None] * I
    bx = E[..., 0, 2] * p0 + E[..., 0, 3] * pd
    bv = E[..., 1, 2] * p0 + E[..., 1, 3] * pd
    A = jnp.concatenate(
        [jnp.concatenate([T @ Axx, T @ Axv], -1), jnp.concatenate([T @ Avx, T @ Avv], -1)], -2
    )
    b = jnp.concatenate([jnp.einsum("irs,is->ir", T, bx), jnp.einsum("irs,is->ir", T, bv)], -1)
    return A, b


def _to_physical(md: Modes, K, F, z, static_correction: bool):
    r = md.omega.shape[1]
    U = jnp.einsum("inr,ir->in", md.Phi, z[:, :r])
    V = jnp.einsum("inr,ir->in", md.Phi, z[:, r:])
    if static_correction:
        # Mode-acceleration correction: the static part of the modes left out.
        Us = jnp.linalg.solve(K, F[..., None])[..., 0]
        Ur = jnp.einsum("inr,ir->in", md.Phi, jnp.einsum("inr,in->ir", md.Phi, F) / md.omega**2)
        U = U + Us - Ur
    return U, V


@eqx.filter_jit
def _ked_periodic(
    M: Float[ArrayLike, "n N N"],
    K: Float[ArrayLike, "n N N"],
    F: Float[ArrayLike, "n N"],
    period: ArrayLike,
    damping: AbstractDamping,
    *,
    n_modes: int | None = None,
    pose_modes_: Modes | None = None,
    static_correction: bool = False,
) -> KEDResponse:
    """Periodic steady-state elastic response by modal superposition (press paper, Eqs. 38-44).

    **Arguments:**

    - `M, K`: mass and stiffness at ``n`` equally spaced poses over one period, (n, N, N).
    - `F`: load at each pose, (n, N), N and N m (``-M Uddot_r`` for KED).
    - `period`: duration of one revolution, s.
    - `damping`: a classical damping law (:class:`ModalDamping`, :class:`RayleighDamping`).
    - `n_modes`: modes kept (lowest), default all.
    - `pose_modes_`: modes at each pose, if already computed (they do not depend on speed).
    - `static_correction`: add the static part of the truncated modes (mode-acceleration method).

    **Returns:** :class:`KEDResponse` at the n poses, with ``U[n] = U[0]`` implied.
    """
    M, K, F = jnp.asarray(M), jnp.asarray(K), jnp.asarray(F)
    n = M.shape[0]
    dt = period / n
    md = pose_modes(M, K, n_modes) if pose_modes_ is None else pose_modes_
    A, b = _modal_maps(md, M, F, damping, dt)

    def compose(carry, ab):
        P, c = carry
        Ai, bi = ab
        return (Ai @ P, Ai @ c + bi), None

    r2 = A.shape[-1]
    (P, c), _ = jax.lax.scan(compose, (jnp.eye(r2), jnp.zeros(r2)), (A, b))
    z0 = jnp.linalg.solve(jnp.eye(r2) - P, c)

    def run(z, ab):
        Ai, bi = ab
        return Ai @ z + bi, z

    _, z = jax.lax.scan(run, z0, (A, b))
    U, V = _to_physical(md, K, F, z, static_correction)
    return KEDResponse(t=jnp.arange(n) * dt, U=U, V=V)


@eqx.filter_jit
def _ked_transient(
    M: Float[ArrayLike, "n N N"],
    K: Float[ArrayLike, "n N N"],
    F: Float[ArrayLike, "n N"],
    period: ArrayLike,
    damping: AbstractDamping,
    n_periods: int = 1,
    *,
    n_modes: int | None = None,
    pose_modes_: Modes | None = None,
) -> KEDResponse:
    """Elastic response by modal superposition from rest at ``t = 0`` over ``n_periods`` revolutions.

    Arguments as :func:`ked_periodic`. **Returns:** :class:`KEDResponse` at ``n * n_periods`` poses.
    """
    M, K, F = jnp.asarray(M), jnp.asarray(K), jnp.asarray(F)
    n = M.shape[0]
    dt = period / n
    md = pose_modes(M, K, n_modes) if pose_modes_ is None else pose_modes_
    A, b = _modal_maps(md, M, F, damping, dt)
    A = jnp.tile(A, (n_periods, 1, 1))
    b = jnp.tile(b, (n_periods, 1))

    def run(z, ab):
        Ai, bi = ab
        return Ai @ z + bi, z

    _, z = jax.lax.scan(run, jnp.zeros(A.shape[-1]), (A, b))
    tile = lambda x: jnp.tile(x, (n_periods,) + (1,) * (x.ndim - 1))
    md_t = Modes(omega=tile(md.omega), Phi=tile(md.Phi))
    U, V = _to_physical(md_t, tile(K), tile(F), z, False)
    return KEDResponse(t=jnp.arange(n * n_periods) * dt, U=U, V=V)


@eqx.filter_jit
def _newmark(
    M: Float[ArrayLike, "n N N"],
    C: Float[ArrayLike, "n N N"],
    K: Float[ArrayLike, "n N N"],
    F: Float[ArrayLike, "n N"],
    period: ArrayLike,
    n_periods: int = 4,
    substeps: int = 1,
    U0: Float[ArrayLike, " N"] | None = None,
) -> KEDResponse:
    """Direct time integration of ``M(t) U'' + C(t) U' + K(t) U = F(t)`` (Newmark, average acceleration).

    The matrices and load at the n poses of a period are interpolated linearly in time between
    poses and repeated periodically; with enough periods the damped response settles on the
    periodic steady state, which is what the last period returns.

    **Arguments:**

    - `M, C, K`: (n, N, N) at equally spaced poses; `F`: (n, N).
    - `period`: s. `n_periods`: revolutions integrated (the last is returned).
    - `substeps`: Newmark steps per pose interval.
    - `U0`: initial displacement (default: the static solution at pose 0); starts at rest.

    **Returns:** :class:`KEDResponse` over the last period at the n poses.
    """
    M, C, K, F = (jnp.asarray(x) for x in (M, C, K, F))
    n = M.shape[0]
    h = period / (n * substeps)
    nxt = (jnp.arange(n) + 1) % n
    s = jnp.arange(substeps) / substeps

    def lerp(X):
        # (n, substeps, ...) values at the start of every substep within each pose interval
        Xa, Xb = X, X[nxt]
        w = s.reshape((1, substeps) + (1,) * (X.ndim - 1))
        return ((1 - w) * Xa[:, None] + w * Xb[:, None]).reshape((n * substeps,) + X.shape[1:])

    Ms, Cs, Ks, Fs = lerp(M), lerp(C), lerp(K), lerp(F)
    ns = n * substeps
    nxt_s = (jnp.arange(ns) + 1) % ns
    u = jnp.linalg.solve(K[0], F[0]) if U0 is None else jnp.asarray(U0)
    v = jnp.zeros_like(u)
    a = jnp.linalg.solve(M[0], F[0] - C[0] @ v - K[0] @ u)

    def step(state, k):
        u, v, a = state
        j = nxt_s[k]
        up = u + h * v + 0.25 * h * h * a
        vp = v + 0.5 * h * a
        S = Ms[j] + 0.5 * h * Cs[j] + 0.25 * h * h * Ks[j]
        an = jnp.linalg.solve(S, Fs[j] - Cs[j] @ vp - Ks[j] @ up)
        un = up + 0.25 * h * h * an
        vn = vp + 0.5 * h * an
        return (un, vn, an), (u, v)

    ks = jnp.tile(jnp.arange(ns), n_periods)
    _, (U, V) = jax.lax.scan(step, (u, v, a), ks)
    U = U[-ns:][::substeps]
    V = V[-ns:][::substeps]
    return KEDResponse(t=jnp.arange(n) * (period / n), U=U, V=V)


def ked_periodic(M, K, F, period, damping, *, n_modes=None, pose_modes_=None, static_correction=False) -> KEDResponse:
    return _ked_periodic(
        M, K, F, jnp.asarray(period, float), damping,
        n_modes=n_modes, pose_modes_=pose_modes_, static_correction=static_correction,
    )


def ked_transient(M, K, F, period, damping, n_periods=1, *, n_modes=None, pose_modes_=None) -> KEDResponse:
    return _ked_transient(M, K, F, jnp.asarray(period, float), damping, n_periods, n_modes=n_modes, pose_modes_=pose_modes_)


def newmark(M, C, K, F, period, n_periods=4, substeps=1, U0=None) -> KEDResponse:
    return _newmark(M, C, K, F, jnp.asarray(period, float), n_periods, substeps, U0)


ked_periodic.__doc__ = _ked_periodic.__doc__
ked_transient.__doc__ = _ked_transient.__doc__
newmark.__doc__ = _newmark.__doc__
