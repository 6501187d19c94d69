"""Measured torques on the wrong scale: a unit or a current-to-torque constant left out of a case.

A motor-current column read as torque (its scale forgotten), a gear ratio missing or a unit
mistaken multiplies a joint's measured torque by a constant. The library's drive gain
(``drive_gain``: a torque constant or a gear's efficiency off) stops at tens of per cent, so the
forward selection would name whichever candidate absorbs most of a larger one (a torque offset
closing a 5316 % gap to 951 %). The check: the gain that
best maps the nominal model's torque onto the measured one, per loaded joint; a gain far from 1
that alone closes most of that joint's misfit is a scale error of the data, named before any
effect is. Each joint is judged on its own: a light wrist joint logged in motor current is as
wrong as a torso, however little of the robot's torque it carries.

A torque channel that reads (nearly) nothing where the model predicts a torque of its own is dead
(:func:`dead_channels`): a sensor left unpowered reads a constant offset plus noise, and its
misfit, thousands of per cent, would veto every candidate.
"""

from __future__ import annotations

import numpy as np

from . import _set as T
from ...effects._registry import PAYLOAD

GAIN_LIMIT = 3.0  # a measured torque GAIN_LIMIT x the model's, or 1/GAIN_LIMIT of it: beyond any payload
# or inertia error a diagnosis could name (an unmodelled payload heavier than the arm's own links)
CLOSES = 0.5  # ... and the gain alone leaves at most this fraction of the joint's misfit
TRIVIAL = 0.05  # a joint whose predicted torque's RMS is below this fraction of its measured one is not judged
NOISE_SNR = 3.0  # ... nor one whose predicted torque's RMS is below 3 x the noise its filtered residual keeps
DEAD_SPREAD = 0.05  # a channel whose measured spread is below this fraction of its nominal predicted spread,
FOLLOWS = 0.5  # ... and that does not follow the prediction (|correlation| below this: not a scale error), is dead
OWN_SHARE = 1e-3  # ... judged only where the joint's nominal spread is at least this share of the set's largest


def _kept(s, j) -> np.ndarray:
    """(N,) bool: the samples of joint ``j`` of set ``s`` that enter the fits (a clipping sensor's do not)."""
    return np.ones(s.tau.shape[0], bool) if getattr(s, "weight", None) is None else s.weight[:, j] > 0


def dead_channels(s, names) -> dict:
    """``{channel: reason}``: the torque channels of set ``s`` whose measured spread is below
    :data:`DEAD_SPREAD` of the nominal (CAD) model's spread along the same motion, where the model
    predicts a torque of its own (:data:`OWN_SHARE` of the set's largest joint spread), and whose
    reading does not follow the prediction (absolute correlation below :data:`FOLLOWS`; a channel that does
    is on a wrong scale, :func:`torque_scale_suspects`)."""
    F = T._filtered(s, "F0")
    nom = F.std(axis=0)
    top = float(np.max(nom)) if nom.size else 0.0
    out = {}
    for j, ch in enumerate(names):
        k = _kept(s, j)
        y, p = s.tau[k, j], F[k, j]
        if y.size < 3 or not np.all(np.isfinite(y)) or nom[j] <= OWN_SHARE * top or not nom[j] > 0:
            continue
        sy = float(y.std())
        if sy >= DEAD_SPREAD * nom[j]:
            continue
        r = float(np.corrcoef(y, p)[0, 1]) if sy > 0 and p.std() > 0 else 0.0
        if abs(r) < FOLLOWS:
            out[ch] = (f"dead against the model: its spread {sy:.3g} N m is {sy / nom[j]:.2g} of the {nom[j]:.3g} N m "
                       f"the nominal model predicts along the same motion, and it does not follow it (correlation "
                       f"{r:.2f})")
    return out


def torque_scale_suspects(pb, state) -> list[dict]:
    """``[{dataset, joint, gain, misfit, misfit_after_gain, offset, misfit_after_offset}]``: joints of
    the torque training sets, each judged on its own where the model predicts a torque of its own
    (its RMS at least :data:`TRIVIAL` of the measured one's and :data:`NOISE_SNR` x the set's noise),
    whose measured torque is best matched by the model's times a gain beyond [1/:data:`GAIN_LIMIT`,
    :data:`GAIN_LIMIT`] that closes at least 1 - :data:`CLOSES` of the misfit (relative RMS, of the
    measured torque's RMS); ``offset`` [N m] is the constant that, added to the model's torque
    instead, matches it best, and ``misfit_after_offset`` what it leaves (:func:`scale_reason` names
    the better of the two). Masked samples (a clipping sensor's) are left out."""
    out = []
    for s in pb.ttrain:
        pred = T.predict(state.tfit, s)
        for j in range(pb.n):
            if not np.isfinite(s.scale[j]):
                continue
            k = _kept(s, j)
            p, y = pred[k, j], s.tau[k, j]
            energy = float(p @ p)
            if not (np.isfinite(energy) and energy > 0):
                continue
            rms_p = float(np.sqrt(np.mean(p**2)))
            norm = float(np.sqrt(np.mean(y**2))) or 1.0
            noise = float(s.noise[j]) if getattr(s, "noise", None) is not None else 0.0
            if rms_p < TRIVIAL * norm or rms_p < NOISE_SNR * noise:
                continue
            gain = float(p @ y / energy)
            before = float(np.sqrt(np.mean((y - p) ** 2))) / norm
            after = float(np.sqrt(np.mean((y - gain * p) ** 2))) / norm
            if (gain > GAIN_LIMIT or gain < 1.0 / GAIN_LIMIT) and after <= CLOSES * before:
                # a constant missing from the log (a current's zero, a counterbalance the model does
                # not hold, gravity on a torso whose drive reads only the rest) also maps the model
                # onto it by a gain near 0: say which of the two fits
                c = float(np.mean(y - p))
                after_offset = float(np.sqrt(np.mean((y - p - c) ** 2))) / norm
                out.append(dict(dataset=s.name, joint=pb.names[j], gain=gain, misfit=before, misfit_after_gain=after,
                                offset=c, misfit_after_offset=after_offset))
    return _not_a_payload(pb, state, out)


def _not_a_payload(pb, state, suspects: list[dict]) -> list[dict]:
    """The suspects a payload does not explain: an unmodelled load at the tool multiplies a light
    distal joint's torque many times over (a wrist carrying 2 kg where the model has its own 0.3),
    which a gain matches as well; fitted as a rigid body (:func:`._torque_terms.nearest_rigid_body`)
    it matches every joint at once, which no scale error of one channel does. A suspect joint whose
    misfit the payload leaves at most where the gain leaves it is no scale error."""
    if not suspects or state.tfit is None or any(getattr(s, "robot", None) is None for s in pb.ttrain):
        return suspects  # (sets without their robot: no payload's columns to fit)
    from ._terms import make_term

    fit = T.fit_with(state.tfit.terms, state.tfit.delay, make_term(PAYLOAD, None), pb.ttrain,
                     getattr(pb, "inertia", None))
    pred = {s.name: T.predict(fit, s) for s in pb.ttrain}
    out = []
    for d in suspects:
        s = next(s for s in pb.ttrain if s.name == d["dataset"])
        j = pb.names.index(d["joint"])
        k = _kept(s, j)
        y = s.tau[k, j]
        norm = float(np.sqrt(np.mean(y**2))) or 1.0
        left = float(np.sqrt(np.mean((y - pred[s.name][k, j]) ** 2))) / norm
        if left > d["misfit_after_gain"]:
            out.append(d)
    return out


def _offset_fits(d: dict) -> bool:
    """Whether a constant added to the model's torque also closes the joint's misfit (on a joint
    whose model torque hardly varies, gravity on a torso, the two cannot be told apart)."""
    return d.get("offset") is not None and d["misfit_after_offset"] <= CLOSES * d["misfit"]


def scale_reason(suspects: list[dict]) -> str:
    """The stop reason for a case whose torques look off scale."""
    def one(d):
        alt = f", or {abs(d['offset']):.4g} N m {'below' if d['offset'] < 0 else 'above'} it" if _offset_fits(d) else ""
        return f"{d['joint']} in {d['dataset']} ({d['gain']:.3g} x the model{alt})"

    why = "a unit, a gear ratio or a current-to-torque constant is likely wrong (case.yaml: the torque columns' scale)"
    if any(_offset_fits(d) for d in suspects):
        why += (", or the log leaves out a constant torque (a current's zero; gravity that a counterbalance or the "
                "drive's own controller carries; case.yaml: torque_offset)")
    return (f"the measured torques look off scale: the model's torque times a constant matches them far better than the "
            f"model itself ({', '.join(one(d) for d in suspects)}); {why}, and no effect is named until it is fixed")
