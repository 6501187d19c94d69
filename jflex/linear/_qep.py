"""Eigenpairs of a lightly damped quadratic eigenproblem by Newton's method from the undamped modes.

``(lambda^2 M + lambda C + K) psi = 0`` for M symmetric positive definite. The undamped
problem ``K phi = w^2 M phi`` is symmetric (Cholesky + ``eigh``: cheap and batched); in its
mass-normalised modal coordinates the damped problem reads ``(lambda^2 I + lambda C~ + K~) y = 0``
with C~, K~ nearly diagonal, so each undamped mode is an excellent start for Newton's method on
``(y, lambda)`` with the normalisation ``y_r = 1``. The Newton matrix is solved by elimination in
an order (the other modes first, the mode itself last) whose pivots are bounded away from zero
while the modes are distinct, so no pivoting and no LAPACK call per posture is needed: the whole
solve is elementwise work that vectorises over a batch of postures. This is what makes posture
sweeps fast; ``jnp.linalg.eig`` (LAPACK ``geev`` per matrix) costs several times more.

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

_ITERS = 5
_TOL = 1e-8


def _solve_ordered(A, b, r):
    """Solve A x = b (lists of complex scalars, n x n) by Gaussian elimination eliminating every
    index but ``r`` first and ``r`` last (static order, no pivoting)."""
    n = len(b)
    order = [k for k in range(n) if k != r] + [r]
    rows = [[A[i][j] for j in order] for i in order]
    rhs = [b[i] for i in order]
    for k in range(n):
        inv = 1.0 / rows[k][k]
        for i in range(k + 1, n):
            f = rows[i][k] * inv
            rows[i] = [rows[i][j] - f * rows[k][j] if j > k else None for j in range(n)]
            rhs[i] = rhs[i] - f * rhs[k]
    x = [None] * n
    for k in reversed(range(n)):
        acc = rhs[k]
        for j in range(k + 1, n):
            acc = acc - rows[k][j] * x[j]
        x[k] = acc / rows[k][k]
    out = [None] * n
    for pos, k in enumerate(order):
        out[k] = x[pos]
    return out


def _newton_step(Kt, Ct, lam, y, r):
    """One Newton step for mode r on (y with y_r = 1, lam) of (lam^2 I + lam Ct + Kt) y = 0.

    Matrices and vectors are lists of scalars: under ``vmap`` every entry is one array over the
    batch and every operation elementwise (tiny batched matmuls and gathers are slow on CPU)."""
    n = len(y)
    lam2 = lam * lam
    Q = [[(lam2 if i == j else 0.0) + lam * Ct[i][j] + Kt[i][j] for j in range(n)] for i in range(n)]
    F = [sum(Q[i][j] * y[j] for j in range(n)) for i in range(n)]
    dQy = [2.0 * lam * y[i] + sum(Ct[i][j] * y[j] for j in range(n)) for i in range(n)]
    # unknowns: y_k for k != r (column k of Q) and lam (column r: y_r is fixed at 1)
    J = [[dQy[i] if j == r else Q[i][j] for j in range(n)] for i in range(n)]
    d = _solve_ordered(J, [-f for f in F], r)
    return lam + d[r], [y[k] + d[k] if k != r else y[k] for k in range(n)]


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
    lams, cols = [], []
    for r in range(n):
        cands = [k for k in (r - 1, r + 1) if 0 <= k < n]

        def pair(k):
            a, d = lam0[r], lam0[k]
            b, c = -0.5 * Ct[r, k], -0.5 * Ct[k, r]
            half = 0.5 * (a - d)
            disc = jnp.sqrt(half * half + b * c)
            disc = jnp.where(jnp.real(jnp.conj(half) * disc) >= 0, disc, -disc)  # the branch that tends to a
            mu = 0.5 * (a + d) + disc
            den = mu - d
            yk = jnp.where(jnp.abs(den) > 0, c / jnp.where(jnp.abs(den) > 0, den, 1.0), 0.0)
            return mu, yk

        (mu, yk), k = pair(cands[0]), cands[0]
        y = jnp.zeros(n, complex).at[r].set(1.0)
        if len(cands) == 2:
            mu2, yk2 = pair(cands[1])
            use2 = jnp.abs(w[cands[1]] - w[r]) < jnp.abs(w[cands[0]] - w[r])
            mu = jnp.where(use2, mu2, mu)
            y = y.at[cands[0]].set(jnp.where(use2, 0.0, yk)).at[cands[1]].set(jnp.where(use2, yk2, 0.0))
        else:
            y = y.at[k].set(yk)
        lams.append(mu)
        cols.append(y)
    return jnp.stack(lams), jnp.stack(cols, axis=1)


def qep_newton(M, C, K, iters: int = _ITERS):
    """The n eigenpairs with Im lambda > 0 of ``(lambda^2 M + lambda C + K) psi = 0`` (underdamped).

    **Returns:** ``(lam (n,), psi (n, n))``: eigenvalues in the order of the undamped modes
    (ascending undamped frequency) and mode shapes in physical coordinates (columns).
    """
    M, C, K = (jnp.asarray(A, dtype=float) for A in (M, C, K))
    n = M.shape[0]
    L = jnp.linalg.cholesky(M)
    Linv = jax.scipy.linalg.solve_triangular(L, jnp.eye(n, dtype=M.dtype), lower=True)
    Ks = Linv @ K @ Linv.T
    w2, U = jnp.linalg.eigh(0.5 * (Ks + Ks.T))
    Phi = Linv.T @ U  # mass-normalised undamped modes
    Kt, Ct = Phi.T @ K @ Phi, Phi.T @ C @ Phi

    def solve(Kt, Ct, w2, lam=None, Y=None, iters=iters):
        K_, C_ = [[Kt[i, j] for j in range(n)] for i in range(n)], [[Ct[i, j] for j in range(n)] for i in range(n)]
        if lam is None:
            lam, Y = _start(Ct, w2)
        lams, ys = [], []
        for r in range(n):  # static: each mode has its own elimination order
            lr, y = lam[r], [Y[k, r] for k in range(n)]
            for _ in range(iters):
                lr, y = _newton_step(K_, C_, lr, y, r)
            lams.append(lr)
            ys.append(jnp.stack(y))
        return jnp.stack(lams), jnp.stack(ys, axis=1)

    sg = jax.lax.stop_gradient
    lam, Y = solve(sg(Kt), sg(Ct), sg(w2))
    # one step with gradients: exact first derivatives at the converged point
    lam, Y = solve(Kt, Ct, w2, sg(lam), sg(Y), iters=1)

    # checks: converged residual, Im > 0, distinct eigenvalues
    eye = jnp.eye(n, dtype=Kt.dtype)
    scale = jnp.abs(lam) ** 2 + jnp.abs(lam) * jnp.max(jnp.abs(Ct)) + jnp.max(jnp.abs(Kt))
    res = jnp.stack([jnp.linalg.norm((lam[r] ** 2 * eye + lam[r] * Ct + Kt) @ Y[:, r]) / jnp.linalg.norm(Y[:, r]) for r in range(n)])
    bad = jnp.any(~(res <= _TOL * scale)) | jnp.any(~(lam.imag > 0))
    if n > 1:
        gaps = jnp.abs(lam[:, None] - lam[None, :]) + jnp.eye(n) * jnp.inf
        bad = bad | jnp.any(gaps <= 1e-6 * jnp.abs(lam)[:, None])
    lam = eqx.error_if(
        lam, bad,
        "modal analysis with solver='newton' did not converge to distinct underdamped modes at this posture "
        "(heavy or overdamped damping, repeated or unstable modes); use solver='eig'",
    )
    return lam, Phi.astype(complex) @ Y
