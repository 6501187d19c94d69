"""The nominal identification's inertial part: the CAD inertial parameters refitted on the torque
training data, pulled toward CAD by a prior and kept within a CAD tolerance.

A real robot's CAD is off by a few per cent in mass and by centimetres in the centre of mass; left
in the nominal model, that error reads as a payload, a compensator or backlash. So the nominal
torque model is ``tau = Y(q, qd, qdd) (pi_cad + delta) + terms``, with ``delta`` (10 n, the
Pinocchio order per link) fitted together with the nominal friction:

$$ \\min \\; \\|W r\\|^2 + w\\,\\hat\\sigma^2 \\sum_i (\\delta_i / s_i)^2, \\qquad |\\delta_i| \\le 2 s_i, $$

where ``s`` is the CAD tolerance per parameter (mass ``MASS_TOL`` relative, centre of mass
``COM_TOL`` [m], rotational inertia ``2 MASS_TOL`` relative plus the COM shift), ``sigma`` the
normalised training residual (the prior's weight is relative to the noise, a Gaussian MAP
estimate) and ``w`` the user's ``inertia_prior`` weight. Directions the data cannot see (non-base
combinations) stay at CAD. An effect far outside the tolerance (a payload of tens of per cent of
the last link) is not absorbed: the bound stops it, and the candidates see the rest.
"""

from __future__ import annotations

import dataclasses

import numpy as np

MASS_TOL = 0.05  # relative CAD mass error, prior std (the bound is 2 x: 10 %)
COM_TOL = 0.01  # [m] CAD centre-of-mass error per axis, prior std (the bound: 2 cm)
MIN_WEIGHT = 1e-6  # a trace of prior always: the non-base directions must stay at CAD


@dataclasses.dataclass
class InertiaPrior:
    """The inertial block of the nominal torque model (numpy, shapes (10 n,))."""

    pi0: np.ndarray  # CAD parameters
    scale: np.ndarray  # prior std s per parameter
    weight: float  # user's prior weight w (0: bounds and a trace of prior only)
    sigma: float = 0.02  # normalised residual level the prior is weighed against (updated by the fit)
    reach: float = 2.0  # the box: |delta| <= reach x scale

    def beyond(self, delta, reach: float | None = None) -> np.ndarray:
        """(10 n,) bool: the parameters of ``delta`` past ``reach`` (default: the box's) x scale."""
        r = self.reach if reach is None else reach
        return np.abs(np.asarray(delta, float)) > r * self.scale * (1 + 1e-6)

    @property
    def size(self) -> int:
        return self.pi0.size

    def bounds(self):
        return -self.reach * self.scale, self.reach * self.scale

    def penalty(self) -> np.ndarray:
        """Diagonal added to the normal equations of ``delta``."""
        w = max(self.weight, MIN_WEIGHT) * self.sigma**2
        return w / self.scale**2


def inertia_prior(robot, weight: float = 1.0) -> InertiaPrior:
    """Prior and tolerance of the CAD inertial parameters of ``robot`` (see the module doc)."""
    P = np.asarray(robot.inertia, dtype=float).reshape(-1, 10)
    s = np.zeros_like(P)
    m_ref = max(float(np.max(np.abs(P[:, 0]))), 1e-9)
    for i, p in enumerate(P):
        m = abs(p[0])
        c = p[1:4] / m if m > 1e-9 * m_ref else np.zeros(3)
        I = np.abs(p[[4, 6, 9]]).max()
        s[i, 0] = MASS_TOL * m
        s[i, 1:4] = MASS_TOL * np.abs(p[1:4]) + m * COM_TOL
        s[i, 4:] = 2 * MASS_TOL * I + m * COM_TOL * (2 * np.linalg.norm(c) + COM_TOL)
    # a massless link (a frame) stays massless: a tiny scale, so its columns are held
    s = np.maximum(s, 1e-12 * max(float(np.abs(P).max()), 1.0))
    return InertiaPrior(P.ravel().copy(), s.ravel(), float(weight))


def tolerance_spread(prior: InertiaPrior, residuals, step: float = 1e-3) -> dict:
    """Per data set, the spread [% NRMSE, one std] of its gap that the CAD inertias' tolerance
    alone gives (``u ~ N(0, I)``, ``delta = s u``, ``s`` the prior's scale), to first order: the
    Frobenius norm of the residual's Jacobian in ``u``, times 100, by forward differences.
    ``residuals(delta)``: ``{name: vector}`` at the inertial parameters CAD + ``delta`` (10 n,),
    each vector's sum of squares the set's NRMSE^2."""
    s = np.asarray(prior.scale, float)
    r0 = residuals(np.zeros(s.size))
    acc = dict.fromkeys(r0, 0.0)
    for p in np.flatnonzero(s > 1e-9 * max(float(s.max()), 1e-12)):
        d = np.zeros(s.size)
        d[p] = step * s[p]
        for k, r in residuals(d).items():
            c = (r - r0[k]) / step
            acc[k] += float(c @ c)
    return {k: float(np.sqrt(v) * 100) for k, v in acc.items()}


# the 10 inertial parameters of a link (Pinocchio order) and their units
PARAM_NAMES = ("m", "m cx", "m cy", "m cz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
PARAM_UNITS = ("kg", "kg m", "kg m", "kg m", "kg m^2", "kg m^2", "kg m^2", "kg m^2", "kg m^2", "kg m^2")


def link_moves(robot, pi0, delta, prior: InertiaPrior | None = None) -> list[dict]:
    """Per link: mass and centre of mass before (CAD) and after the refit, and whether a bound was
    reached (the CAD tolerance did not suffice: a sign of a payload or a grossly wrong CAD), with
    the parameters at their bound and their change (``bound_parameters``; a rotational inertia
    may reach it while mass and centre of mass barely move)."""
    P0 = np.asarray(pi0, float).reshape(-1, 10)
    P1 = P0 + np.asarray(delta, float).reshape(-1, 10)
    lo, hi = prior.bounds() if prior is not None else (None, None)
    out = []
    for i, (a, b) in enumerate(zip(P0, P1)):
        if abs(a[0]) < 1e-12 and abs(b[0]) < 1e-12:
            continue
        ca = a[1:4] / a[0] if abs(a[0]) > 1e-12 else np.zeros(3)
        cb = b[1:4] / b[0] if abs(b[0]) > 1e-12 else np.zeros(3)
        d = np.asarray(delta, float).reshape(-1, 10)[i]
        at_bound, which = False, []
        if lo is not None:
            l, h = lo.reshape(-1, 10)[i], hi.reshape(-1, 10)[i]
            hit = (np.abs(d - l) < 1e-6 * np.abs(l)) | (np.abs(d - h) < 1e-6 * np.abs(h))
            # a parameter held at zero (a massless frame's: both bounds ~0) is no bound reached
            hit &= np.abs(h - l) > 1e-9 * max(float(np.max(np.abs(h - l))), 1e-300)
            at_bound = bool(np.any(hit))
            which = [f"{PARAM_NAMES[k]} {'+' if abs(d[k] - h[k]) <= abs(d[k] - l[k]) else '-'}{abs(d[k]):.4g} {PARAM_UNITS[k]}"
                     for k in np.flatnonzero(hit)]
        out.append({
            "link": robot.link_names[i], "mass_cad_kg": float(a[0]), "mass_kg": float(b[0]),
            "mass_change_pct": float(100 * (b[0] - a[0]) / a[0]) if abs(a[0]) > 1e-12 else None,
            "com_cad_m": [float(v) for v in ca], "com_m": [float(v) for v in cb],
            "com_shift_m": float(np.linalg.norm(cb - ca)), "at_tolerance_bound": at_bound,
            "bound_parameters": which,
        })
    return out
