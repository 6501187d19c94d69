"""Candidate signatures: a cheap score per torque candidate before any refit (the correlation of
the training residual with the candidate's columns), used to prune the candidates refitted, and
the number of parameters each candidate adds (the information criterion's penalty)."""

from __future__ import annotations

import numpy as np

from ..torque import _set as T
from ..frequency._kinds import frequency_kinds
from ..torque._terms import KINDS, make_term
from ._view import CandidateView, ProblemView, StateView


def n_params(c: CandidateView, user=None, torque: bool = True, problem: ProblemView | None = None) -> int:
    """Parameters ``c`` adds (its kind's count, searched hyper-parameters included): the torque
    side's when there are torque data (a payload's 10 inertial parameters), else the frequency
    side's on ``problem``'s training data (a payload's mass and centre of mass on FRFs, its mass on
    modal tables alone: :class:`._frequency_kinds.ToolPayload`)."""
    if user and c in user:
        return user[c].size
    if torque and c.effect in KINDS:
        return KINDS[c.effect].n_params
    kind = frequency_kinds().get(c.effect)
    if kind is None:
        return KINDS[c.effect].n_params
    return kind.params(problem) if problem is not None else kind.n_params


def signatures(problem: ProblemView, state: StateView, cands) -> dict:
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


def signature_name(effect: str) -> str:
    """What a candidate's residual looks like: its kind says it (the torque side's first)."""
    kind = KINDS.get(effect) or frequency_kinds().get(effect)
    return kind.signature if kind is not None else ""


INDISTINGUISHABLE = 1e-6  # relative residual of a candidate's columns off the inertial columns' span


def indistinguishable_from_inertia(problem: ProblemView, cands) -> dict:
    """Torque candidates whose columns lie in the span of the inertial parameters the nominal
    identification refits (``{candidate: relative residual}``): on these motions they are the same
    torques as a change of the links' inertias (a rotor's inertia regroups with its link's about
    the joint axis, a payload is the last link's parameters), so the refit holds them up to the
    CAD tolerance, and only what lies beyond it can show as a gap. Empty when the nominal
    identification keeps the CAD inertias."""
    if not problem.ttrain or problem.inertia is None:
        return {}
    YtY = sum(T.weighted_inertia_columns(st)[1] for st in problem.ttrain)
    d = np.sqrt(np.maximum(np.diag(YtY), 1e-300))
    pinv = np.linalg.pinv(YtY / d[:, None] / d[None, :], rcond=1e-12)
    out = {}
    for c in cands:
        if c.effect not in KINDS or c in problem.user:
            continue
        term = make_term(c.effect, c.joint)
        if not term.n_params:
            continue
        YtA = AtA = 0.0
        for st in problem.ttrain:
            Yw = T.weighted_inertia_columns(st)[0]
            A = (T.term_columns(term, st) * (1.0 / st.scale)[None, :, None]).reshape(st.tau.size, -1)
            YtA, AtA = YtA + Yw.T @ A, AtA + A.T @ A
        total = float(np.trace(AtA))
        if total <= 0:
            continue
        Ys = YtA / d[:, None]
        rel = max(total - float(np.trace(Ys.T @ pinv @ Ys)), 0.0) / total
        if rel < INDISTINGUISHABLE:
            out[c] = rel
    return out
