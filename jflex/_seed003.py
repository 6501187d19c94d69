"""Seed 003's rigid dynamics in terms of its identified base parameters (thesis, Appendix B).

The thesis gives M(q) and G(q) of the Staubli TX200 and Kuka KR90 (3 positioning joints) as a
regressor ``Phi(q, qdd)`` times 15 base parameters. ``realisation_matrix`` finds link inertial
parameters (jflex order) that reproduce each column, so the identified values can drive a
:class:`jflex.Model` (the realisation is not unique and need not be physical per link).
"""

from __future__ import annotations

import numpy as np

from ._dynamics import regressor
from ._sweep import sweep

G0 = -9.81  # Appendix B writes gravity torques with g = -9.81 (z up): -g cos(q2) psi_3 > 0


def appendix_b_columns(q, qdd, a1, a2):
    """Columns 1..15 of the thesis regressor Phi at zero velocity (link part: rotor terms 16-18
    and compensator/friction columns are handled by the effects). Shape (3, 15).

    Phi(3,13) and Phi(3,15) read ``qd_1`` in the OCR text; symmetry of M(q) with Phi(1,13),
    Phi(1,15) says ``qdd_1``, which is what is used here.
    """
    q1, q2, q3 = q
    d1, d2, d3 = qdd
    s, c = np.sin, np.cos
    P = np.zeros((3, 15))
    P[0, 0] = d1
    P[0, 2] = 2 * a1 * d1 * c(q2)
    P[0, 3] = -2 * a1 * d1 * s(q2)
    P[0, 4] = d1 / 2 - d1 * c(2 * q2) / 2
    P[0, 5] = -d2 * s(q2)
    P[0, 6] = -d1 * s(2 * q2)
    P[0, 7] = -d2 * c(q2)
    P[0, 9] = d1 * (a2 * c(q3) + a2 * c(2 * q2 + q3) + 2 * a1 * c(q2 + q3))
    P[0, 10] = -d1 * (a2 * s(q3) + a2 * s(2 * q2 + q3) + 2 * a1 * s(q2 + q3))
    P[0, 11] = d1 / 2 - d1 * c(2 * q2 + 2 * q3) / 2
    P[0, 12] = -(d2 + d3) * s(q2 + q3)
    P[0, 13] = -d1 * s(2 * q2 + 2 * q3)
    P[0, 14] = -(d2 + d3) * c(q2 + q3)
    P[1, 1] = d2
    P[1, 2] = -G0 * c(q2)
    P[1, 3] = G0 * s(q2)
    P[1, 5] = -d1 * s(q2)
    P[1, 7] = -d1 * c(q2)
    P[1, 8] = d2 + d3
    P[1, 9] = 2 * a2 * d2 * c(q3) - G0 * c(q2 + q3) + a2 * d3 * c(q3)
    P[1, 10] = G0 * s(q2 + q3) - 2 * a2 * d2 * s(q3) - a2 * d3 * s(q3)
    P[1, 12] = -d1 * s(q2 + q3)
    P[1, 14] = -d1 * c(q2 + q3)
    P[2, 8] = d2 + d3
    P[2, 9] = a2 * d2 * c(q3) - G0 * c(q2 + q3)
    P[2, 10] = G0 * s(q2 + q3) - a2 * d2 * s(q3)
    P[2, 12] = -d1 * s(q2 + q3)
    P[2, 14] = -d1 * c(q2 + q3)
    return P


def realisation_matrix(robot, a1, a2, n_samples=60, seed=0):
    """R (30, 15): link inertial parameters (jflex order) realising each base parameter, i.e.
    ``regressor(q, 0, qdd) @ R = Phi_1..15(q, qdd)`` (least squares over random samples; the
    realisation is not unique and need not be physical, only its base combinations matter)."""
    rng = np.random.default_rng(seed)
    Q = rng.uniform(-np.pi, np.pi, (n_samples, 3))
    D = rng.normal(size=(n_samples, 3))
    Y = sweep(lambda q, d: regressor(robot, q, 0 * q, d), Q, D, progress=False).reshape(-1, 30)
    P = np.concatenate([appendix_b_columns(q, d, a1, a2) for q, d in zip(Q, D)])
    R, *_ = np.linalg.lstsq(Y, P, rcond=None)
    rel = np.linalg.norm(Y @ R - P, axis=0) / np.maximum(np.linalg.norm(P, axis=0), 1e-300)
    return R, rel
