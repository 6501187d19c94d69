"""Candidate signatures: a cheap score per torque candidate before any refit (the correlation of
the training residual with the candidate's columns), used to prune the candidates refitted, and
the number of parameters each candidate adds (the information criterion's penalty)."""

from __future__ import annotations

import numpy as np

from ._problem import TORQUE_EFFECTS, Candidate, Problem, State
from . import _torque as T

def n_params(c: Candidate, user=None, torque: bool = True) -> int:
    """Parameters ``c`` adds; a payload is its 10 inertial parameters on torque data, one point
    mass on FRF/modal data alone."""
    if user and c in user:
        return user[c].size
    if c.effect == "payload" and not torque:
        return 1
    return {"stribeck_friction": 3, "gravity_compensator": 4, "payload": 10, "orthogonal_compliance": 4,
            "link_flexibility": 4, "joint_flexibility": 2, "fractional_damping": 2,
            "backlash": 1 + len(T.BACKLASH_PULSES)}.get(c.effect, 1)


def signatures(problem: Problem, state: State, cands) -> dict:
    """A cheap score per torque candidate before any refit: the largest |correlation| between the
    training residual and the candidate's columns (sign of velocity for Coulomb, posture harmonics
    for compensators, d tau/dt for a delay, held sign x gravity stiffness for backlash)."""
    out = {}
    if not problem.ttrain:
        return out
    res = [(T.predict(state.tfit, s) - s.tau) / s.scale for s in problem.ttrain]
    for c in cands:
        if c.effect not in TORQUE_EFFECTS:
            continue
        best = 0.0
        for s, r in zip(problem.ttrain, res):
            if c.effect == "sensor_delay":
                cols = (np.gradient(T.predict(state.tfit, s), s.t, axis=0) / s.scale)[:, :, None]
            else:
                hs = {"stribeck_friction": [T.STRIBECK_VS[1]], "backlash": [0.01, (T.LOADED, 0.01)]}.get(c.effect, [None])
                cols = np.concatenate([T.term_columns(T.Term(c.effect, c.joint, h), s) for h in hs], axis=2)
                cols = cols / s.scale[None, :, None]
            for k in range(cols.shape[2]):
                v = cols[:, :, k].ravel()
                nv = np.linalg.norm(v)
                if nv > 0:
                    best = max(best, abs(v @ r.ravel()) / (nv * np.linalg.norm(r)))
        out[c] = best
    return out


SIGNATURE_NAMES = {
    "viscous_friction": "correlation with joint velocity", "coulomb_friction": "correlation with sign of velocity",
    "stribeck_friction": "sign of velocity, larger at low speed", "rotor_inertia": "correlation with joint acceleration",
    "gravity_compensator": "posture harmonics of the joint angle", "backlash": "dead zone at reversals of motion or of the transmitted torque",
    "payload": "tool-mass regressor columns", "sensor_delay": "phase lag: correlation with d tau/dt",
    "joint_flexibility": "extra FRF peak / unmatched mode; in torques, the link lagging under load (tau_j / k)", "orthogonal_compliance": "extra FRF peak / unmatched mode",
    "link_flexibility": "extra FRF peak / unmatched mode", "hysteretic_damping": "damping ratio flat in frequency",
    "fractional_damping": "damping ratio growing as w^(alpha-1)",
}
