"""Physically consistent inertial parameters through the log-Cholesky parametrisation of the
pseudo-inertia (Rucker and Wensing, 2022), and the fits that use it.

``J = [[Sigma, h], [h^T, m]]`` with ``Sigma = tr(I)/2 1 - I`` (I about the body origin) is
positive definite exactly when the mass is positive and the inertia about the centre of mass
satisfies the triangle inequalities. ``J = U U^T`` with U upper triangular,
``U = e^alpha [[e^d1, s12, s13, t1], [0, e^d2, s23, t2], [0, 0, e^d3, t3], [0, 0, 0, 1]]``, so
every real 10-vector ``(alpha, d1, d2, d3, s12, s23, s13, t1, t2, t3)`` is a consistent body.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._errors import DataError, ParameterError
from .._spatial import inertia_matrix3


def log_cholesky_pseudo_inertia(theta):
    """The pseudo-inertia ``J = U U^T`` (4, 4) of a log-Cholesky vector (10,) (see the module)."""
    a, d1, d2, d3, s12, s23, s13, t1, t2, t3 = [theta[i] for i in range(10)]
    z = jnp.zeros_like(a)
    U = jnp.exp(a) * jnp.array(
        [[jnp.exp(d1), s12, s13, t1], [z, jnp.exp(d2), s23, t2], [z, z, jnp.exp(d3), t3], [z, z, z, z + 1.0]]
    )
    return U @ U.T


def pseudo_inertia(pi) -> np.ndarray:
    """The pseudo-inertia ``J = [[Sigma, h], [h^T, m]]`` (4, 4) of 10 inertial parameters
    (Pinocchio order), on the host."""
    pi = np.asarray(pi, dtype=float)
    I = inertia_matrix3(pi, np)  # on the host: a fit's start and checks run no JAX program
    S = 0.5 * np.trace(I) * np.eye(3) - I
    return np.block([[S, pi[1:4, None]], [pi[None, 1:4], np.array([[pi[0]]])]])


def pseudo_inertia_to_params(J, xp=jnp):
    """The 10 inertial parameters (Pinocchio order ``[m, m c, I about the origin]``) of a
    pseudo-inertia ``J = [[Sigma, h], [h^T, m]]`` (..., 4, 4); linear in ``J`` (so a frame change
    ``T J T^T`` of the body is one of its parameters). ``xp``: the array module (``numpy`` on the host)."""
    S = J[..., :3, :3]
    tr = S[..., 0, 0] + S[..., 1, 1] + S[..., 2, 2]
    return xp.stack([J[..., 3, 3], J[..., 0, 3], J[..., 1, 3], J[..., 2, 3], tr - S[..., 0, 0], -S[..., 0, 1],
                      tr - S[..., 1, 1], -S[..., 0, 2], -S[..., 1, 2], tr - S[..., 2, 2]], axis=-1)


def log_cholesky_to_inertia(theta):
    """10 inertial parameters (Pinocchio order) of a log-Cholesky vector (10,)."""
    return pseudo_inertia_to_params(log_cholesky_pseudo_inertia(theta))


def inertia_to_log_cholesky(pi, eps: float = 1e-9):
    """Inverse map; a body on (or beyond) the boundary of consistency is first nudged inside by
    adding ``eps`` (relative) to its pseudo-inertia's eigenvalues."""
    w, V = np.linalg.eigh(pseudo_inertia(pi))
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
    w = np.linalg.eigvalsh(pseudo_inertia(pi))
    return bool(w.min() >= -tol * max(abs(w).max(), 1.0))


class PhysicalResult(NamedTuple):
    """``theta`` (p,): consistent standard parameters (inertial block first, then the rest);
    ``inertia`` (n, 10); ``cost``: final ``0.5 |r|^2`` (of the weighted rows, over every sample
    also when the fit ran on the compressed system); ``steps``; ``stop``: which rule ended the fit
    (``"converged"``, ``"cost stalled"``, ``"step limit"``); ``result``: the same as an
    optimistix code.

    When the best consistent body lies on the boundary of consistency (a zero principal moment),
    its log-Cholesky coordinates run off to infinity, so the solver's step criterion is never met
    although the cost has long stopped changing: the fit then stops once ``stall_steps`` steps
    lower the chi-square by less than ``stall_chi2``."""

    theta: np.ndarray
    inertia: np.ndarray
    cost: float
    steps: int
    stop: str

    @property
    def result(self):
        import optimistix as optx  # here, not at import: 0.3 s of a fresh process's fit

        return optx.RESULTS.successful if self.stop == "converged" else optx.RESULTS.nonlinear_max_steps_reached


def _row_weights(weights, m: int):
    w = np.asarray(weights, dtype=float).ravel()
    if w.size == 0 or m % w.size:
        raise ParameterError(
            f"physical_fit: weights must have one entry per row of A ({m}) or per joint (a divisor of {m}, "
            f"rows stacked sample by sample), got {w.size}"
        )
    if not np.all(np.isfinite(w)) or np.any(w <= 0):
        raise ParameterError("physical_fit: weights must be finite and > 0")
    return np.tile(w, m // w.size)


def physical_fit(
    A,
    y,
    n_links: int,
    *,
    prior=None,
    prior_weight: float = 1e-6,
    weights=None,
    compress: bool | None = None,
    solver=None,
    max_steps: int = 200,
    stall_chi2: float = 0.1,
    stall_steps: int = 20,
) -> PhysicalResult:
    """Physically consistent least squares: ``min |W (A theta - y)|^2 + w^2 |theta - prior|^2``
    with the first ``10 n_links`` entries of theta parametrised per body by log-Cholesky.

    Works with the full (rank-deficient) standard regressor: the prior (a CAD estimate) fills in
    what the data cannot see, and with ``A = K`` (the base-parameter map) and ``y = psi`` it lifts
    base parameters back to a full consistent set.

    **Arguments:**

    - ``A`` (m, p), ``y`` (m,): a linear model in the standard parameters (inertial block first).
    - ``prior`` (p,): reference parameters, also the start (must be consistent or near it);
      default: 1 kg point masses at the origin-ish and zeros for the rest.
    - ``prior_weight``: ``w`` relative to the scale of ``A``.
    - ``weights``: row weights ``W`` (m,), or one per joint (n_joints,) for rows stacked sample
      by sample as :meth:`Regressor.stack` does (e.g. ``1 / sigma_j`` from :func:`wls`).
    - ``compress``: fit the QR-compressed system ``(R, Q^T W y)`` of ``W A = Q R`` instead of
      every sample: ``|W (A theta - y)|^2 = |R theta - Q^T W y|^2 + const``, so the objective,
      its gradient and Gauss-Newton matrix, and hence the answer, are the same, at the cost of
      p rows instead of m per step. Default: when m > 2 p.
    - ``solver``: an optimistix least-squares solver, run in rounds of ``stall_steps`` steps;
      default (``None``): Levenberg-Marquardt compiled as one loop, which starts in a third of
      the time of optimistix's (the first call of a fresh process is what a user waits for).
    - ``max_steps``: the solver's step limit.
    - ``stall_chi2``, ``stall_steps``: stop when ``stall_steps`` steps lower the chi-square
      ``|r|^2 / s^2`` by less than ``stall_chi2``, with ``s^2 = |r|^2 / m`` the mean squared
      residual of the m rows: a change no statistical test could see (a body at the boundary of
      consistency never meets the solver's step criterion).

    **Returns:** :class:`PhysicalResult`.
    """
    A = np.asarray(A, dtype=float)
    y = np.asarray(y, dtype=float).ravel()
    m, p = A.shape
    if y.shape[0] != m:
        raise ParameterError(f"physical_fit: y has {y.shape[0]} entries but A has {m} rows")
    ni = 10 * n_links
    if p < ni:
        raise ParameterError(f"physical_fit: A has {p} columns, fewer than 10 x {n_links} inertial parameters")
    for name, v in (("A", A), ("y", y)):
        if not np.all(np.isfinite(v)):
            bad = np.argwhere(~np.isfinite(v))[0]
            raise DataError(f"physical_fit: {name} contains NaN/inf (first at index {tuple(int(i) for i in bad)})")
    if weights is not None:
        wr = _row_weights(weights, m)
        A, y = A * wr[:, None], y * wr
    if prior is None:
        prior = np.zeros(p)
        prior[:ni] = np.tile([1.0, 0, 0, 0, 1e-2, 0, 1e-2, 0, 0, 1e-2], n_links)
    prior = np.asarray(prior, dtype=float)
    if prior.shape != (p,) or not np.all(np.isfinite(prior)):
        raise ParameterError(f"physical_fit: prior must be {p} finite numbers (one per column of A), got shape {prior.shape}"
                             + ("" if prior.shape != (p,) else " with NaN/inf"))
    u0_in = np.concatenate([inertia_to_log_cholesky(prior[10 * i : 10 * i + 10]) for i in range(n_links)])
    u0 = np.concatenate([u0_in, prior[ni:]])
    # scales of the full system (|A|_F is |R|_F): the compressed fit solves the same problem
    scale = np.linalg.norm(A) / np.sqrt(m)
    w = prior_weight * scale
    # Rows are scaled by the column norms so that kg and kg m^2 columns weigh alike.
    ynorm = max(float(np.linalg.norm(y)), 1e-300)
    offset = 0.0  # |y|^2 - |Q^T y|^2: the part of the cost no theta can change
    if compress if compress is not None else m > 2 * p:
        # R of [A y] holds R, Q^T y and the residual no theta reaches: Q itself (m x p) is never formed
        Rxy = _r_factor(A, y)
        A, y = Rxy[:p, :p], Rxy[:p, p]
        offset = float(Rxy[p, p] ** 2) if Rxy.shape[0] > p else 0.0
    # device_put, not jnp.asarray: the latter compiles a copy program per shape (jax 0.10)
    args = tuple(jax.device_put(np.asarray(v, dtype=float)) for v in (A, y, prior, w, ynorm))
    resid, finish, marquardt = _programs(n_links)
    # placed as the programs' own results are, so a second fit reuses the first's programs
    u0 = jax.device_put(u0, jax.devices()[0])
    if solver is None:
        u, steps, code = marquardt(u0, args, jax.device_put(np.array([m, offset, stall_chi2, 1e-12, 1e-14])),
                                   jax.device_put(np.array([max_steps, stall_steps])))
        steps, stop = int(steps), ("step limit", "converged", "cost stalled")[int(code)]
    else:
        u, steps, stop = _optimistix_rounds(resid, finish, solver, u0, args, m, offset, max_steps,
                                            stall_chi2, stall_steps)
    th, r = (np.asarray(v) for v in finish(u, args))
    return PhysicalResult(th, th[:ni].reshape(n_links, 10), float(_cost(r, offset)), steps, stop)


def _cost(r, offset):
    """``0.5 |W (A theta - y)|^2`` over every sample from the fitted rows' unscaled residual ``r``
    and the compressed part ``offset`` no theta reaches (NumPy or traced)."""
    return 0.5 * (r @ r + offset)


def _stalled(prev, cost, m, stall_chi2):
    """The stall rule: the chi-square change ``2 (prev - cost) / s^2``, ``s^2 = 2 cost / m``, is at
    most ``stall_chi2`` (NumPy or traced)."""
    return (prev - cost) * m / cost <= stall_chi2


def _r_factor(A, y, block: int = 4096):
    """R of the QR factorisation of ``[A y]``, block of rows by block of rows (each stacked under
    the R so far): the same R up to the signs of its rows, in about 40 % of the time of one QR of
    the tall matrix (blocks that stay in cache) and with no copy of it."""
    R = np.zeros((0, A.shape[1] + 1))
    for i in range(0, A.shape[0], block):
        R = np.linalg.qr(np.vstack([R, np.column_stack([A[i : i + block], y[i : i + block]])]), mode="r")
    return R


def _optimistix_rounds(resid, finish, solver, u, args, m, offset, max_steps, stall_chi2, stall_steps):
    """The fit by a user's optimistix solver, in rounds of ``stall_steps`` steps (the same
    compiled solver each round: same function and shapes) with the stall rule between rounds."""
    import optimistix as optx

    def cost_of(u):
        return float(_cost(np.asarray(finish(u, args)[1]), offset))

    steps, prev, stop = 0, cost_of(u), "step limit"
    while steps < max_steps:
        sol = optx.least_squares(resid, solver, u, args=args, max_steps=min(stall_steps, max_steps - steps),
                                 throw=False)
        u, steps = sol.value, steps + int(sol.stats["num_steps"])
        cost = cost_of(u)
        if sol.result == optx.RESULTS.successful:
            stop = "converged"
            break
        if _stalled(prev, cost, m, stall_chi2):
            stop = "cost stalled"
            break
        prev = cost
    return u, steps, stop


_PROGRAMS: dict = {}


def _programs(n_links: int):
    """The residual ``(u, args) -> r``, ``(u, args) -> (theta, unscaled r)`` and the compiled
    default fit (:func:`_marquardt`) for ``n_links`` bodies, made once per count: the data
    ``args = (A, y, prior, w, ynorm)`` are arguments, not constants, so every fit of the same
    shapes in a process runs the programs already compiled."""
    if n_links not in _PROGRAMS:
        ni = 10 * n_links

        def theta_of(u):
            inert = jax.vmap(log_cholesky_to_inertia)(u[:ni].reshape(n_links, 10)).ravel()
            return jnp.concatenate([inert, u[ni:]])

        def resid(u, args):
            A, y, prior, w, ynorm = args
            th = theta_of(u)
            return jnp.concatenate([(A @ th - y) / ynorm, w * (th - prior) / ynorm])

        def finish(u, args):
            return theta_of(u), resid(u, args) * args[4]

        # XLA:CPU's optimisation level 0: the programs compile in a fraction of the time, and
        # their arithmetic on a (2 p, p) system is no part of the wait
        quick = {"xla_backend_optimization_level": 0}
        _PROGRAMS[n_links] = (resid, jax.jit(finish, compiler_options=quick),
                              jax.jit(functools.partial(_marquardt, theta_of, resid), compiler_options=quick))
    return _PROGRAMS[n_links]


def _marquardt(theta_of, resid, u, args, reals, ints):
    """Levenberg-Marquardt (Levenberg's damping, Nielsen's update of it) for
    :func:`physical_fit`, with its stall rule, as one ``lax.while_loop``.

    Optimistix's solver compiles in about 2.6 s for an 8-body fit, most of a fresh process's
    consistent identification, and this loop in a third of a second; the fit is small (p
    unknowns, ``2 p`` rows once compressed) and its Jacobian is the data's linear map times the
    per-body log-Cholesky Jacobian, so normal equations serve.

    ``reals = (m, offset, stall_chi2, rtol, atol)``, ``ints = (max_steps, stall_steps)``; returns
    ``(u, steps, code)`` with code 0 at the step limit, 1 converged (the step and the cost change
    within ``atol + rtol |.|``), 2 stalled (``stall_steps`` steps lowered the chi-square of the
    ``m`` rows by at most ``stall_chi2``)."""
    m, offset, stall_chi2, rtol, atol = reals
    max_steps, stall_steps = ints
    A, _, _, w, ynorm = args

    def body(c):
        u, r, f, lam, nu, k, window_cost, window_start, _ = c
        T = jax.jacfwd(theta_of)(u)  # block diagonal: each body's log-Cholesky map, 1 elsewhere
        J = jnp.concatenate([A @ T, w * T]) / ynorm
        g, H = J.T @ r, J.T @ J
        # Levenberg's damping lam 1, from 1e-3 of H's largest diagonal entry: Marquardt's diag(H)
        # lets the directions the data barely see (a 1e-12 diagonal) take steps the exponentials
        # of the log-Cholesky map overshoot by orders of magnitude
        lam = jnp.where(k == 0, 1e-3 * jnp.max(jnp.diag(H)), lam)
        step = -_spd_solve(H + lam * jnp.eye(H.shape[0], dtype=H.dtype), g)
        r_new = resid(u + step, args)
        f_new = 0.5 * r_new @ r_new
        # the model's decrease 0.5 |r|^2 - 0.5 |r + J step|^2, in Madsen, Nielsen and Tingleff's
        # form: a sum of two positive terms, with no cancellation as the residual vanishes
        predicted = 0.5 * (lam * step @ step - g @ step)
        rho = (f - f_new) / predicted
        ok = jnp.isfinite(f_new) & (predicted > 0) & (rho > 1e-4)
        small_step = jnp.max(jnp.abs(step) / (atol + rtol * jnp.abs(u))) < 1.0
        converged = small_step & ((ok & (jnp.abs(f - f_new) <= atol + rtol * f)) | (predicted <= atol + rtol * f))
        u, r, f = (jnp.where(ok, new, old) for new, old in ((u + step, u), (r_new, r), (f_new, f)))
        lam = jnp.where(ok, lam * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), lam * nu)
        nu = jnp.where(ok, 2.0, 2.0 * nu)
        k = k + 1
        window_end = k - window_start >= stall_steps
        cost = _cost(r * ynorm, offset)
        stalled = window_end & _stalled(window_cost, cost, m, stall_chi2)
        window_cost, window_start = jnp.where(window_end, cost, window_cost), jnp.where(window_end, k, window_start)
        code = jnp.where(converged, 1, jnp.where(stalled, 2, 0))
        return u, r, f, lam, nu, k, window_cost, window_start, code

    r0 = resid(u, args)
    zero = jnp.zeros((), ints.dtype)
    init = (u, r0, 0.5 * r0 @ r0, jnp.asarray(0.0, u.dtype), jnp.asarray(2.0, u.dtype), zero,
            _cost(r0 * ynorm, offset), zero, zero)
    out = jax.lax.while_loop(lambda c: (c[-1] == 0) & (c[5] < max_steps), body, init)
    return out[0], out[5], out[-1]


def _spd_solve(M, b):
    """``M^-1 b`` for a symmetric positive definite M (p, p) by Cholesky, in ``lax`` loops: a
    LAPACK call would make jaxlib import scipy.linalg (0.4 s of a fresh process) for a solve of
    p^3 / 3 flops. Not positive definite: NaN."""
    n = M.shape[0]
    idx = jnp.arange(n)

    def column(j, L):
        v = M[:, j] - L @ L[j]  # L[j] holds the finished columns k < j only
        return L.at[:, j].set(jnp.where(idx >= j, v / jnp.sqrt(v[j]), 0.0))

    L = jax.lax.fori_loop(0, n, column, jnp.zeros_like(M))
    z = jax.lax.fori_loop(0, n, lambda i, z: z.at[i].set((b[i] - L[i] @ z) / L[i, i]), jnp.zeros_like(b))
    return jax.lax.fori_loop(
        0, n, lambda k, x: x.at[n - 1 - k].set((z[n - 1 - k] - L[:, n - 1 - k] @ x) / L[n - 1 - k, n - 1 - k]),
        jnp.zeros_like(b))
