"""Physically consistent inertial parameters through the log-Cholesky parametrisation of the
pseudo-inertia (Rucker and Wensing, 2022), and the fits that use it.

``J = [[Sigma, h], [h^T, m]]`` with ``Sigma = tr(I)/2 1 - I`` (I about the body origin) is
positive definite exactly when the mass is positive and the inertia about the centre of mass
satisfies the triangle inequalities. ``J = U U^T`` with U upper triangular,
``U = e^alpha [[e^d1, s12, s13, t1], [0, e^d2, s23, t2], [0, 0, e^d3, t3], [0, 0, 0, 1]]``, so
every real 10-vector ``(alpha, d1, d2, d3, s12, s23, s13, t1, t2, t3)`` is a consistent body.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._errors import ParameterError
from .._spatial import inertia_matrix3


def log_cholesky_pseudo_inertia(theta):
    """The pseudo-inertia ``J = U U^T`` (4, 4) of a log-Cholesky vector (10,) (see the module)."""
    a, d1, d2, d3, s12, s23, s13, t1, t2, t3 = [theta[i] for i in range(10)]
    z = jnp.zeros_like(a)
    U = jnp.exp(a) * jnp.array(
        [[jnp.exp(d1), s12, s13, t1], [z, jnp.exp(d2), s23, t2], [z, z, jnp.exp(d3), t3], [z, z, z, z + 1.0]]
    )
    return U @ U.T


def pseudo_inertia_to_params(J):
    """The 10 inertial parameters (Pinocchio order ``[m, m c, I about the origin]``) of a
    pseudo-inertia ``J = [[Sigma, h], [h^T, m]]`` (..., 4, 4); linear in ``J`` (so a frame change
    ``T J T^T`` of the body is one of its parameters)."""
    S = J[..., :3, :3]
    tr = S[..., 0, 0] + S[..., 1, 1] + S[..., 2, 2]
    return jnp.stack([J[..., 3, 3], J[..., 0, 3], J[..., 1, 3], J[..., 2, 3], tr - S[..., 0, 0], -S[..., 0, 1],
                      tr - S[..., 1, 1], -S[..., 0, 2], -S[..., 1, 2], tr - S[..., 2, 2]], axis=-1)


def log_cholesky_to_inertia(theta):
    """10 inertial parameters (Pinocchio order) of a log-Cholesky vector (10,)."""
    return pseudo_inertia_to_params(log_cholesky_pseudo_inertia(theta))


def inertia_to_log_cholesky(pi, eps: float = 1e-9):
    """Inverse map; a body on (or beyond) the boundary of consistency is first nudged inside by
    adding ``eps`` (relative) to its pseudo-inertia's eigenvalues."""
    pi = np.asarray(pi, dtype=float)
    m, h = pi[0], pi[1:4]
    I = np.asarray(inertia_matrix3(pi))
    S = 0.5 * np.trace(I) * np.eye(3) - I
    J = np.block([[S, h[:, None]], [h[None, :], np.array([[m]])]])
    w, V = np.linalg.eigh(J)
    floor = eps * max(abs(w).max(), 1e-12)
    J = (V * np.maximum(w, floor)) @ V.T
    P = np.eye(4)[::-1]
    L = np.linalg.cholesky(P @ J @ P)
    U = P @ L @ P
    e = U[3, 3]
    U = U / e
    return np.array(
        [np.log(e), np.log(U[0, 0]), np.log(U[1, 1]), np.log(U[2, 2]), U[0, 1], U[1, 2], U[0, 2], U[0, 3], U[1, 3], U[2, 3]]
    )


def is_consistent(pi, tol: float = 1e-9) -> bool:
    """Whether 10 inertial parameters describe a physical body (pseudo-inertia PSD)."""
    pi = np.asarray(pi, dtype=float)
    I = np.asarray(inertia_matrix3(pi))
    S = 0.5 * np.trace(I) * np.eye(3) - I
    J = np.block([[S, pi[1:4, None]], [pi[None, 1:4], np.array([[pi[0]]])]])
    w = np.linalg.eigvalsh(J)
    return bool(w.min() >= -tol * max(abs(w).max(), 1.0))


class PhysicalResult(NamedTuple):
    """``theta`` (p,): consistent standard parameters (inertial block first, then the rest);
    ``inertia`` (n, 10); ``cost``: final ``0.5 |r|^2``; ``steps``; ``result``: optimistix code."""

    theta: np.ndarray
    inertia: np.ndarray
    cost: float
    steps: int
    result: object


def physical_fit(
    A,
    y,
    n_links: int,
    *,
    prior=None,
    prior_weight: float = 1e-6,
    solver=None,
    max_steps: int = 200,
) -> PhysicalResult:
    """Physically consistent least squares: ``min |A theta - y|^2 + w^2 |theta - prior|^2`` with the
    first ``10 n_links`` entries of theta parametrised per body by log-Cholesky.

    Works with the full (rank-deficient) standard regressor: the prior (a CAD estimate) fills in
    what the data cannot see, and with ``A = K`` (the base-parameter map) and ``y = psi`` it lifts
    base parameters back to a full consistent set.

    **Arguments:**

    - ``A`` (m, p), ``y`` (m,): a linear model in the standard parameters (inertial block first).
    - ``prior`` (p,): reference parameters, also the start (must be consistent or near it);
      default: 1 kg point masses at the origin-ish and zeros for the rest.
    - ``prior_weight``: ``w`` relative to the scale of ``A``.
    - ``solver``: an optimistix least-squares solver (default Levenberg-Marquardt).

    **Returns:** :class:`PhysicalResult`.
    """
    A = jnp.asarray(A, dtype=float)
    y = jnp.asarray(y, dtype=float).ravel()
    p = A.shape[1]
    ni = 10 * n_links
    if p < ni:
        raise ParameterError(f"physical_fit: A has {p} columns, fewer than 10 x {n_links} inertial parameters")
    if prior is None:
        prior = np.zeros(p)
        prior[:ni] = np.tile([1.0, 0, 0, 0, 1e-2, 0, 1e-2, 0, 0, 1e-2], n_links)
    prior = np.asarray(prior, dtype=float)
    u0_in = np.concatenate([inertia_to_log_cholesky(prior[10 * i : 10 * i + 10]) for i in range(n_links)])
    u0 = jnp.asarray(np.concatenate([u0_in, prior[ni:]]))
    scale = jnp.linalg.norm(A) / np.sqrt(A.shape[0])
    w = prior_weight * scale
    prior_j = jnp.asarray(prior)
    # Rows are scaled by the column norms so that kg and kg m^2 columns weigh alike.
    ynorm = jnp.maximum(jnp.linalg.norm(y), 1e-300)

    def theta_of(u):
        inert = jax.vmap(log_cholesky_to_inertia)(u[:ni].reshape(n_links, 10)).ravel()
        return jnp.concatenate([inert, u[ni:]])

    def resid(u, _):
        th = theta_of(u)
        return jnp.concatenate([(A @ th - y) / ynorm, w * (th - prior_j) / ynorm])

    solver = solver if solver is not None else optx.LevenbergMarquardt(rtol=1e-12, atol=1e-14)
    sol = optx.least_squares(resid, solver, u0, max_steps=max_steps, throw=False)
    th = np.asarray(theta_of(sol.value))
    r = np.asarray(resid(sol.value, None)) * float(ynorm)
    return PhysicalResult(th, th[:ni].reshape(n_links, 10), float(0.5 * r @ r), int(sol.stats["num_steps"]), sol.result)
