"""The rigid-body payload fitted on torque data: whether its ten inertial parameters are a body's,
and the nearest body's when they are not."""

from __future__ import annotations

import numpy as np

from ...identify._physical import pseudo_inertia, pseudo_inertia_to_params


PSEUDO_INERTIA_TOL = 1e-6  # relative to its largest eigenvalue: rounding, not a body's inertia
NEAREST_ITERATIONS = 5000  # at most, of the nearest rigid body's projected gradient (a few hundred on a planar arm)


def payload_implausible(theta) -> str | None:
    """Why payload parameters ``[m, m cx, m cy, m cz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` (inertia about
    the last body's origin) are no rigid body's, else None: a body has a positive mass and a
    positive semi-definite pseudo-inertia ``[[tr(I)/2 1 - I, m c], [m c^T, m]]`` (its second moments
    of mass; Wensing, Kim and Slotine, "Linear matrix inequalities for physically consistent
    inertial parameter identification"), which also holds the triangle inequalities of the
    principal moments. A fit outside that set absorbs something else."""
    p = np.asarray(theta, float)
    m, h = float(p[0]), p[1:4]
    if not m > 0:
        return (f"a payload of mass {m:.4g} kg with first moment {np.round(h, 4).tolist()} kg m is no rigid body "
                "(a body carried has a positive mass)")
    lam = np.linalg.eigvalsh(pseudo_inertia(p))
    if lam[0] < -PSEUDO_INERTIA_TOL * max(abs(lam[-1]), 1e-300):
        return (f"a payload of {m:.4g} kg whose inertia [Ixx, Iyy, Izz] = {np.round(p[[4, 6, 9]], 5).tolist()} kg m^2 about "
                f"the tool body's origin and first moment {np.round(h, 4).tolist()} kg m no rigid body has (its pseudo-"
                f"inertia matrix has the negative eigenvalue {lam[0]:.3g})")
    return None


def _body_map() -> np.ndarray:
    """(10, 10): inertial parameters from a pseudo-inertia's Frobenius-normed entries (linear)."""
    return np.stack([pseudo_inertia_to_params(_mat(e), np) for e in np.eye(10)], axis=1)


_IU = np.triu_indices(4)
_W = np.where(_IU[0] == _IU[1], 1.0, np.sqrt(2.0))  # a symmetric matrix's entries, Frobenius-normed


def _vec(J):
    return J[_IU] * _W


def _mat(v):
    J = np.zeros((4, 4))
    J[_IU] = v / _W
    return J + np.triu(J, 1).T


def _psd(v):
    lam, U = np.linalg.eigh(_mat(v))
    return _vec((U * np.maximum(lam, 0.0)) @ U.T)


_BODY_MAP = _body_map()


def nearest_rigid_body(theta, S, *, iterations: int = NEAREST_ITERATIONS, rtol: float = 1e-13) -> np.ndarray:
    """The inertial parameters of a rigid body (positive semi-definite pseudo-inertia) nearest to
    ``theta`` in the metric ``S`` (10 x 10, positive semi-definite): ``min (p - theta)' S (p - theta)``
    over the bodies. The parameters are linear in the pseudo-inertia, so this is a convex problem
    over the cone of positive semi-definite 4 x 4 matrices, solved by accelerated projected
    gradient (FISTA, restarted when the cost rises; the projection cuts the negative eigenvalues).
    ``S`` is singular where the data see nothing (a planar motion sees no out-of-plane moment):
    any body is as near there, and a local search scaled by the seen directions stalled."""
    theta = np.asarray(theta, float)
    A = _BODY_MAP
    H = A.T @ S @ A
    g0 = A.T @ S @ theta
    L = 2.0 * max(float(np.linalg.eigvalsh(H)[-1]), 1e-300)

    def cost(v):
        r = A @ v - theta
        return float(r @ S @ r)

    x = _psd(_vec(pseudo_inertia(theta)))
    y, t, fx = x.copy(), 1.0, cost(x)
    for k in range(iterations):
        xn = _psd(y - 2.0 * (H @ y - g0) / L)
        tn = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * t * t))
        fn = cost(xn)
        y = xn + ((t - 1.0) / tn) * (xn - x)
        if fn > fx:  # momentum overshot: restart from the last point
            y, tn = xn.copy(), 1.0
        done = k > 10 and abs(fx - fn) <= rtol * max(fx, 1e-300)
        x, t, fx = xn, tn, fn
        if done or fx == 0.0:
            break
    return A @ x
