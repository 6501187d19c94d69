"""The nominal identification's inertial part on frequency data: the CAD inertial parameters
refitted on the training FRFs and modal tables when no torque data identify them.

A few per cent of CAD mass error and a centimetre of COM shift move a lightly damped mode by about
its half-power bandwidth, so the complex FRF error of the CAD model at a held-out posture is
tens of per cent (the independent null FRF case: 16.9 % with the CAD inertias, 3.7 % with the true
ones against a 3.5 % noise floor). The nominal joint stiffnesses, fitted on the training postures,
absorb the error there but not its posture dependence. So, as on the torque side
(:mod:`._inertia`), the linear model's inertial parameters are refitted together with the model's
springs, pulled toward CAD by the same prior and held within the same tolerance:

$$ \\min_{x, u} \\; \\|r(x, \\pi_{cad} + s \\odot u)\\|^2 + \\lambda \\|u\\|^2, \\qquad |u_i| \\le 2, $$

``r`` the training residual of :func:`._frequency_model.residual`, ``s`` the CAD tolerance per parameter,
``lambda = w c_0 / N`` the user's ``inertia_prior`` weight ``w`` times the residual level ``c_0``
of the springs-only fit per residual (a Gaussian MAP estimate at that noise level). The mass
matrix, the gravity stiffness and (for payload candidates) their sensitivities are linear in the
inertial parameters: their per-parameter bases are computed once per posture, so a refit costs
no more model evaluations than a springs-only fit.

Thirty-odd inertial parameters can bend any structure toward two training postures: a refit that
leaves a bearing compliance out fits its own postures better and predicts the next one far worse
(the independent orthogonal-compliance case: 34 % held-out with CAD, 96 % refitted), and one that
leaves a fractional damping law out absorbs it on the training postures. So the refit is judged
as any change of the model is (:meth:`._problem.Problem._refit_linear_inertia`): it must pay for
its parameters on the training data (BIC, counting the directions the data see) and close at least
half of the held-out gap; else the nominal model, and its candidates, keep CAD. (Refitting the
inertias again with each candidate was tried: it tripled the time of an FRF case and overfitted
the two training postures the same way, e.g. a fractional damping case 10.2 -> 11.4 % held-out.)

Measured on the independent FRF cases (CAD -> refitted, held-out NRMSE [%], the true inertias in
brackets): null 15.3 -> 2.2 [2.6], hysteretic damping 6.0 -> 2.2, fractional damping 22.2 -> 10.2
[3.7]: two postures do not pin every inertial direction the third one sees.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import scipy.optimize as so

from . import _model as L
from .._inertia import InertiaPrior, tolerance_spread


class _Shifted(L.FrequencyModel):
    """A :class:`._frequency_model.FrequencyModel` whose robot's inertial parameters are CAD plus ``delta``
    (10 n, the model links in Pinocchio's order), with ``M`` and ``K_g`` assembled from cached
    per-parameter bases."""

    def __init__(self, lm: L.FrequencyModel):
        self.robot, self.structure, self.tool = lm.robot, lm.structure, lm.tool
        self.aug, self.coord, self.model_index = lm.aug, lm.coord, lm.model_index
        self.pairs, self.held = lm.pairs, lm.held
        self._base = lm
        self._basis = {}
        self.delta = np.zeros(10 * lm.robot.nq)
        self._cache = {}
        self._psi_cache = lm._psi_cache

    def basis(self, q0):
        key = tuple(np.round(np.asarray(q0, float), 12))
        if key not in self._basis:
            qa = self.posture(q0)
            # M and K_g of the linearisation are linear in the inertial parameters: their Jacobian is the basis
            dM, dK = jax.jacfwd(lambda inert: self._linearization(self.aug.replace(inertia=inert), qa, traced=True))(
                jnp.asarray(self.aug.inertia))
            rows = np.asarray(self.model_index)  # the model links' rows in the augmented robot
            S = len(self.coord)
            dM = np.asarray(dM)[:, :, rows, :].reshape(S, S, -1)
            dK = np.asarray(dK)[:, :, rows, :].reshape(S, S, -1)
            self._basis[key] = (dM, dK)
        return self._basis[key]

    def mats(self, q0):
        P = self._base.mats(q0)
        if not np.any(self.delta):
            return P
        dM, dK = self.basis(q0)
        return L.PostureMats(P.M + dM @ self.delta, P.Kg + dK @ self.delta, P.J, P.dM, P.dKg)


def shifted(lm: L.FrequencyModel, delta) -> L.FrequencyModel:
    """``lm`` with its inertial parameters CAD plus ``delta`` (sharing its cached matrices)."""
    sh = _Shifted(lm)
    sh.delta = np.asarray(delta, float)
    return sh


def refit_linear_inertia(lm: L.FrequencyModel, x, train, prior: InertiaPrior, delta0=None, box: float = 3.0,
                         max_nfev: int = 40):
    """Refit the springs' log parameters ``x`` of ``lm`` (a model of the CAD robot) together with the
    inertial correction (from ``delta0``, default CAD) on the frequency training sets ``train``.
    Returns ``(delta (10 n,), x, gain)``: ``gain`` is the training BIC gain over the model at ``x``,
    ``delta0`` (positive: the refit pays for its parameters)."""
    sh = _Shifted(lm)
    x = np.asarray(x, float)
    nx = x.size
    s = prior.scale
    u0 = np.zeros(s.size) if delta0 is None else np.clip(np.asarray(delta0, float) / s, -2.0, 2.0)
    sh.delta = s * u0
    r0 = L.residual(sh, x, train, peaks=False)
    c0, N = float(r0 @ r0), r0.size
    lam = max(prior.weight, 1e-6) * c0 / N

    def fun(v):
        sh.delta = s * v[nx:]
        r = L.residual(sh, v[:nx], train, peaks=False)
        return np.concatenate([r, np.sqrt(lam) * v[nx:]])

    lo = np.concatenate([x - box, np.full(s.size, -2.0)])
    hi = np.concatenate([x + box, np.full(s.size, 2.0)])
    # links without mass (frames) keep CAD: held by a box of zero width in effect
    free_u = s > 1e-9 * max(float(s.max()), 1e-12)
    lo[nx:][~free_u], hi[nx:][~free_u] = -1e-12, 1e-12
    v0 = np.clip(np.concatenate([x, u0]), lo, hi)
    sol = so.least_squares(fun, v0, method="trf", bounds=(lo, hi), x_scale=1.0, tr_solver="lsmr", max_nfev=max_nfev)
    v = sol.x
    sh.delta = s * v[nx:]
    r1 = L.residual(sh, v[:nx], train, peaks=False)
    c1 = float(r1 @ r1)
    # the directions the training data see: the Jacobian's singular values above the prior's level
    J = sol.jac[:N, nx:]
    sv = np.linalg.svd(J, compute_uv=False) if J.size else np.zeros(0)
    rank = int(np.sum(sv**2 > lam)) if sv.size else 0
    gain = N * np.log(max(c0, 1e-300) / max(c1, 1e-300)) - rank * np.log(N)
    return s * v[nx:], v[:nx], float(gain)


def cad_spread(lm: L.FrequencyModel, x, sets, prior: InertiaPrior, step: float = 1e-3) -> dict:
    """Per modal table in ``sets``: the spread [% NRMSE, one std] of its gap that the CAD inertias'
    tolerance alone gives (``u ~ N(0, I)``, ``delta = s u``), to first order: the Frobenius norm of
    the table's residual Jacobian in ``u``, times 100. When the data cannot identify the inertias
    (the refit does not pay for its parameters), a gap of this size does not fault the model. Modal
    frequencies and damping are smooth in the inertias; an FRF near a lightly damped peak is not
    (a first-order spread there is meaningless), so FRF sets get none."""
    sh = _Shifted(lm)
    modal = [d for d in sets if d.kind == "modal"]

    def residuals(delta):
        sh.delta = delta
        return {d.name: L.residual(sh, x, [d], peaks=False) for d in modal}

    return tolerance_spread(prior, residuals, step)
