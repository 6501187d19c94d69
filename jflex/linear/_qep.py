"""Eigenpairs of a lightly damped quadratic eigenproblem by Newton's method from the undamped modes.

``(lambda^2 M + lambda C + K) psi = 0`` for M symmetric positive definite. The undamped
problem ``K phi = w^2 M phi`` is symmetric (Cholesky + ``eigh``: cheap and batched); in its
mass-normalised modal coordinates the damped problem reads ``(lambda^2 I + lambda C~ + K~) y = 0``
with C~, K~ nearly diagonal, so each undamped mode is an excellent start for Newton's method on
``(y, lambda)`` with the normalisation ``y_r = 1``. The Newton matrix is solved by elimination in
an order (the other modes first, the mode itself last) whose pivots are bounded away from zero
while the modes are distinct, so no pivoting and no LAPACK call per posture is needed: the whole
solve is array work over (modes, n, n) that vectorises over a batch of postures. This is what
makes posture sweeps fast; ``jnp.linalg.eig`` (LAPACK ``geev`` per matrix) costs several times
more. Every mode is solved at once and the iterations and the elimination are ``lax`` loops, so
the traced program has the same size whatever the number of coordinates (an unrolled elimination
per mode and iteration grows as n^4 and took tens of seconds to compile for 14 coordinates).

Valid for underdamped modes (complex pairs): every mode must converge to a distinct eigenvalue
with Im > 0. Both are checked, and a posture where they fail raises (``eqx.error_if``) with the
advice to use ``solver="eig"``. Gradients are exact: the iterations run without gradient and one
last Newton step from the converged point carries them (at a root the derivative of the Newton
map with respect to the data is the implicit-function derivative).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

_ITERS = 5
_TOL = 1e-8


def _orders(n):
    """Static elimination order of each mode r: every other index first, r last (n, n)."""
    return np.array([[k for k in range(n) if k != r] + [r] for r in range(n)], dtype=np.int32)


def _solve_ordered(A, b, order):
    """Solve ``A[r] x = b[r]`` for every r by Gaussian elimination without pivoting in the order
    ``order[r]`` (the permuted system is eliminated in its natural order, then permuted back).

    ``A`` (m, n, n), ``b`` (m, n); ``order`` (m, n) static."""
    m, n = b.shape
    rows = np.arange(m)[:, None]
    Ap = A[rows[:, :, None], order[:, :, None], order[:, None, :]]
    bp = jnp.take_along_axis(b, jnp.asarray(order), axis=1)
    idx = jnp.arange(n)

    def eliminate(k, ab):
        Ap, bp = ab
        pivot_row = jax.lax.dynamic_index_in_dim(Ap, k, axis=1, keepdims=False)  # (m, n)
        pivot = jax.lax.dynamic_index_in_dim(pivot_row, k, axis=1, keepdims=False)  # (m,)
        col = jax.lax.dynamic_index_in_dim(Ap, k, axis=2, keepdims=False)  # (m, n)
        f = jnp.where(idx[None, :] > k, col / pivot[:, None], 0.0)
        bk = jax.lax.dynamic_index_in_dim(bp, k, axis=1, keepdims=False)
        # only the columns right of the pivot matter below (the rest is never read again)
        upd = jnp.where(idx[None, None, :] > k, f[:, :, None] * pivot_row[:, None, :], 0.0)
        return Ap - upd, bp - f * bk[:, None]

    Ap, bp = jax.lax.fori_loop(0, n, eliminate, (Ap, bp))

    def substitute(j, x):
        k = n - 1 - j
        row = jax.lax.dynamic_index_in_dim(Ap, k, axis=1, keepdims=False)  # (m, n)
        # the sum runs over the solved entries right of k (left of k lie eliminated entries)
        acc = jax.lax.dynamic_index_in_dim(bp, k, axis=1, keepdims=False) - jnp.sum(jnp.where(idx > k, row, 0.0) * x, axis=1)
        xk = acc / jax.lax.dynamic_index_in_dim(row, k, axis=1, keepdims=False)
        return jax.lax.dynamic_update_index_in_dim(x, xk, k, axis=1)

    xp = jax.lax.fori_loop(0, n, substitute, jnp.zeros_like(bp))
    inverse = np.argsort(order, axis=1)
    return jnp.take_along_axis(xp, jnp.asarray(inverse), axis=1)


def _newton_step(Kt, Ct, lam, Y):
    """One Newton step for every mode r on (y_r with y_rr = 1, lam_r) of
    ``(lam_r^2 I + lam_r Ct + Kt) y_r = 0``; ``lam`` (n,), ``Y`` (n, n) with the modes as columns."""
    n = lam.shape[0]
    eye = jnp.eye(n, dtype=Kt.dtype)
    Q = lam[:, None, None] ** 2 * eye + lam[:, None, None] * Ct + Kt  # (r, i, j)
    Yr = Y.T  # (r, j)
    F = jnp.einsum("rij,rj->ri", Q, Yr)
    dQy = 2.0 * lam[:, None] * Yr + jnp.einsum("ij,rj->ri", Ct, Yr)
    # unknowns: y_k for k != r (column k of Q) and lam (column r: y_r is fixed at 1)
    J = jnp.where(eye[:, None, :] > 0, dQy[:, :, None], Q)
    d = _solve_ordered(J, -F, _orders(n))
    dlam = jnp.diagonal(d)
    return lam + dlam, Y + jnp.where(eye > 0, 0.0, d.T)


def _start(Ct, w2):
    """Starting eigenpairs in modal coordinates: each undamped mode with its own damping, coupled
    by damping to its nearest neighbour in frequency through the first-order (lambda ~ i w) 2x2
    problem ``lambda y = [[a, b], [c, d]] y``. Near a crossing of two modes, damping mixes them
    strongly and the uncoupled start would cost Newton many more steps."""
    n = w2.shape[0]
    cd = jnp.diagonal(Ct)
    lam0 = -0.5 * cd + 1j * jnp.sqrt(jnp.maximum(w2 - 0.25 * cd**2, 0.0))
    if n == 1:
        return lam0, jnp.eye(1, dtype=complex)
    w = jnp.sqrt(jnp.maximum(w2, 0.0))
    r = np.arange(n)
    left, right = np.maximum(r - 1, 0), np.minimum(r + 1, n - 1)
    # the neighbour: the one above when it is strictly nearer in frequency (or the only one)
    nearer = jnp.abs(w[right] - w) < jnp.abs(w[left] - w)
    k = jnp.where((r == 0) | ((r < n - 1) & nearer), right, left)
    a, d = lam0, lam0[k]
    b, c = -0.5 * Ct[r, k], -0.5 * Ct[k, r]
    half = 0.5 * (a - d)
    disc = jnp.sqrt(half * half + b * c)
    disc = jnp.where(jnp.real(jnp.conj(half) * disc) >= 0, disc, -disc)  # the branch that tends to a
    mu = 0.5 * (a + d) + disc
    den = mu - d
    yk = jnp.where(jnp.abs(den) > 0, c / jnp.where(jnp.abs(den) > 0, den, 1.0), 0.0)
    Y = jnp.eye(n, dtype=complex) + jnp.where(r[:, None] == k[None, :], yk[None, :], 0.0)
    return mu, Y


def qep_newton(M, C, K, iters: int = _ITERS):
    """The n eigenpairs with Im lambda > 0 of ``(lambda^2 M + lambda C + K) psi = 0`` (underdamped).

    **Returns:** ``(lam (n,), psi (n, n))``: eigenvalues in the order of the undamped modes
    (ascending undamped frequency) and mode shapes in physical coordinates (columns).
    """
    # full-precision products: on a GPU, JAX's default float32 matmul rounds through TF32 (about
    # 1e-3), which no residual check of an eigenpair can pass
    with jax.default_matmul_precision("highest"):
        return _qep_newton(M, C, K, iters)


def _qep_newton(M, C, K, iters):
    M, C, K = (jnp.asarray(A, dtype=float) for A in (M, C, K))
    n = M.shape[0]
    L = jnp.linalg.cholesky(M)
    Linv = jax.scipy.linalg.solve_triangular(L, jnp.eye(n, dtype=M.dtype), lower=True)
    Ks = Linv @ K @ Linv.T
    w2, U = jnp.linalg.eigh(0.5 * (Ks + Ks.T))
    Phi = Linv.T @ U  # mass-normalised undamped modes
    Kt, Ct = Phi.T @ K @ Phi, Phi.T @ C @ Phi

    sg = jax.lax.stop_gradient
    Kc, Cc = sg(Kt), sg(Ct)
    lam, Y = _start(Cc, sg(w2))
    lam, Y = jax.lax.fori_loop(0, iters, lambda _, s: _newton_step(Kc, Cc, *s), (lam, Y))
    # one step with gradients: exact first derivatives at the converged point
    lam, Y = _newton_step(Kt, Ct, sg(lam), sg(Y))

    # checks: converged residual, Im > 0, distinct eigenvalues
    eye = jnp.eye(n, dtype=Kt.dtype)
    scale = jnp.abs(lam) ** 2 + jnp.abs(lam) * jnp.max(jnp.abs(Ct)) + jnp.max(jnp.abs(Kt))
    R = jnp.einsum("rij,jr->ir", lam[:, None, None] ** 2 * eye + lam[:, None, None] * Ct + Kt, Y)
    res = jnp.linalg.norm(R, axis=0) / jnp.linalg.norm(Y, axis=0)
    # the relative residual reachable in the working precision: float32 (JFLEX_X64=0) rounds at
    # about 1e-7, far above _TOL, and Newton would be reported as not converged at every posture
    tol = max(_TOL, 64 * float(jnp.finfo(Kt.dtype).eps))
    bad = jnp.any(~(res <= tol * scale)) | jnp.any(~(lam.imag > 0))
    if n > 1:
        gaps = jnp.abs(lam[:, None] - lam[None, :]) + jnp.eye(n) * jnp.inf
        bad = bad | jnp.any(gaps <= 1e-6 * jnp.abs(lam)[:, None])
    lam = eqx.error_if(
        lam, bad,
        "modal analysis with solver='newton' did not converge to distinct underdamped modes at this posture "
        "(heavy or overdamped damping, repeated or unstable modes); use solver='eig'",
    )
    return lam, Phi.astype(complex) @ Y
