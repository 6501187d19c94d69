"""Equation-error estimators on a linear-in-the-parameters model ``A theta = y + e``: ordinary
and weighted least squares (with parameter standard deviations) and instrumental variables."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.linalg

from .._errors import DataError


class LSResult(NamedTuple):
    """Estimate of a linear least-squares problem.

    - ``theta`` (p,): estimate; ``std`` (p,): standard deviations; ``cov`` (p, p).
    - ``sigma2``: residual variance (per joint for WLS, shape (n_joints,)).
    - ``residual`` (m,): ``y - A theta`` (unweighted).
    - ``relative_std`` (p,): ``100 std / |theta|`` [%], the usual identifiability figure.
    - ``cond``: condition number of the (weighted) observation matrix.
    """

    theta: np.ndarray
    std: np.ndarray
    cov: np.ndarray
    sigma2: np.ndarray
    residual: np.ndarray
    relative_std: np.ndarray
    cond: float


def _check(A, y):
    A = np.asarray(A, dtype=float)
    y = np.asarray(y, dtype=float).ravel()
    if A.ndim != 2 or A.shape[0] != y.shape[0]:
        raise DataError(f"least squares: A has shape {A.shape} but y has {y.shape[0]} rows")
    if A.shape[0] < A.shape[1]:
        raise DataError(f"least squares: {A.shape[0]} equations for {A.shape[1]} parameters; record more samples")
    if not (np.isfinite(A).all() and np.isfinite(y).all()):
        raise DataError("least squares: A or y contains NaN/inf")
    return A, y


def _solve(Aw, yw):
    theta, *_ = scipy.linalg.lstsq(Aw, yw, lapack_driver="gelsy")
    s = np.linalg.svd(Aw, compute_uv=False)
    cond = float(s[0] / s[-1]) if s[-1] > 0 else float("inf")
    return theta, cond


def _finish(theta, cov, sigma2, resid, cond):
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(divide="ignore"):
        rel = 100.0 * std / np.abs(theta)
    return LSResult(theta, std, cov, np.asarray(sigma2), resid, rel, cond)


def ols(A, y) -> LSResult:
    """Ordinary least squares ``theta = (A^T A)^-1 A^T y`` (the thesis "Posture Dependent Dynamics in Robotic Machining" Eq. 3.7) with
    ``cov = sigma^2 (A^T A)^-1`` and ``sigma^2 = |y - A theta|^2 / (m - p)``.

    **Arguments:** ``A`` (m, p) full column rank (use base parameters); ``y`` (m,).
    """
    A, y = _check(A, y)
    theta, cond = _solve(A, y)
    r = y - A @ theta
    m, p = A.shape
    sigma2 = r @ r / max(m - p, 1)
    cov = sigma2 * np.linalg.pinv(A.T @ A)
    return _finish(theta, cov, sigma2, r, cond)


def wls(A, y, n_joints: int, iterations: int = 1) -> LSResult:
    """Weighted least squares with one noise level per joint (Gautier's WLS).

    Rows are sample-major (row ``k n + j`` is joint ``j``). The per-joint variances are
    estimated from the OLS residuals (re-estimated ``iterations`` times), rows are weighted by
    ``1 / sigma_j`` and ``cov = (A^T W A)^-1``.
    """
    A, y = _check(A, y)
    if A.shape[0] % n_joints:
        raise DataError(f"wls: {A.shape[0]} rows is not a multiple of n_joints = {n_joints}")
    m, p = A.shape
    theta, _ = _solve(A, y)
    for _ in range(max(1, iterations)):
        r = (y - A @ theta).reshape(-1, n_joints)
        dof = max(r.shape[0] - p / n_joints, 1.0)
        sigma2 = np.maximum((r**2).sum(axis=0) / dof, 1e-300)
        w = np.tile(1.0 / np.sqrt(sigma2), m // n_joints)
        theta, cond = _solve(A * w[:, None], y * w)
    Aw = A * w[:, None]
    cov = np.linalg.pinv(Aw.T @ Aw)
    return _finish(theta, cov, sigma2, y - A @ theta, cond)


def instrumental_variables(A, y, Z) -> LSResult:
    """Instrumental-variable estimate ``theta = (Z^T A)^-1 Z^T y``.

    ``Z`` (m, p) is the regressor built from noise-free signals (e.g. simulated with the previous
    estimate, the IDIM-IV scheme): it removes the bias OLS has when ``A`` is built from noisy
    measured positions.
    """
    A, y = _check(A, y)
    Z = np.asarray(Z, dtype=float)
    if Z.shape != A.shape:
        raise DataError(f"instrumental_variables: Z has shape {Z.shape}, expected A's {A.shape}")
    ZA = Z.T @ A
    theta = np.linalg.solve(ZA, Z.T @ y)
    r = y - A @ theta
    m, p = A.shape
    sigma2 = r @ r / max(m - p, 1)
    ZAi = np.linalg.inv(ZA)
    cov = sigma2 * ZAi @ (Z.T @ Z) @ ZAi.T
    s = np.linalg.svd(Z, compute_uv=False)
    return _finish(theta, cov, sigma2, r, float(s[0] / s[-1]))
