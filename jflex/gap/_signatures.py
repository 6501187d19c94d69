"""Candidate signatures: a cheap score per torque candidate before any refit (the correlation of
the training residual with the candidate's columns), used to prune the candidates refitted, and
the number of parameters each candidate adds (the information criterion's penalty)."""

from __future__ import annotations

import numpy as np

from ._problem import Candidate, Problem, State
from . import _torque as T
from ._torque_terms import BACKLASH_PULSES, KINDS, make_term


def n_params(c: Candidate, user=None, torque: bool = True) -> int:
    """Parameters ``c`` adds; a payload is its 10 inertial parameters on torque data, one point
    mass on FRF/modal data alone."""
    if user and c in user:
        return user[c].size
    if c.effect == "payload" and not torque:
        return 1
    return {"stribeck_friction": 3, "gravity_compensator": 4, "payload": 10, "orthogonal_compliance": 4,
            "link_flexibility": 4, "joint_flexibility": 2, "fractional_damping": 2,
            "backlash": 1 + len(BACKLASH_PULSES)}.get(c.effect, 1)


def signatures(problem: Problem, state: State, cands) -> dict:
    """A cheap score per torque candidate before any refit: the largest |correlation| between the
    training residual and the candidate's columns (sign of velocity for Coulomb, posture harmonics
    for compensators, d tau/dt for a delay, held sign x gravity stiffness for backlash)."""
    out = {}
    if not problem.ttrain:
        return out
    res = [(T.predict(state.tfit, s) - s.tau) / s.scale for s in problem.ttrain]
    for c in cands:
        if c.effect not in KINDS:
            continue
        term = make_term(c.effect, c.joint)
        best = 0.0
        for s, r in zip(problem.ttrain, res):
            cols = term.signature_columns(s, state.tfit) / s.scale[None, :, None]
            for k in range(cols.shape[2]):
                v = cols[:, :, k].ravel()
                nv = np.linalg.norm(v)
                if nv > 0:
                    best = max(best, abs(v @ r.ravel()) / (nv * np.linalg.norm(r)))
        out[c] = best
    return out


# what each candidate's residual looks like: the torque-side kinds say it themselves
SIGNATURE_NAMES = {
    **{name: kind.signature for name, kind in KINDS.items()},
    "orthogonal_compliance": "extra FRF peak / unmatched mode", "link_flexibility": "extra FRF peak / unmatched mode",
    "hysteretic_damping": "damping ratio flat in frequency", "fractional_damping": "damping ratio growing as w^(alpha-1)",
}
