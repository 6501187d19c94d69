"""Measured torques on the wrong scale: a unit or a current-to-torque constant left out of a case.

A motor-current column read as torque (its scale forgotten), a gear ratio missing or a unit
mistaken multiplies a joint's measured torque by a constant. The library's drive gain
(``drive_gain``: a torque constant or a gear's efficiency off) stops at tens of per cent, so the
forward selection would name whichever candidate absorbs most of a larger one (a torque offset
closing a 5316 % gap to 951 %). The check: the gain that
best maps the nominal model's torque onto the measured one, per loaded joint; a gain far from 1
that alone closes most of that joint's misfit is a scale error of the data, named before any
effect is.
"""

from __future__ import annotations

import numpy as np

from . import _torque as T

GAIN_LIMIT = 3.0  # a measured torque GAIN_LIMIT x the model's, or 1/GAIN_LIMIT of it: beyond any payload
# or inertia error a diagnosis could name (an unmodelled payload heavier than the arm's own links)
CLOSES = 0.5  # ... and the gain alone leaves at most this fraction of the joint's misfit
LOADED = 0.05  # joints carrying at least this share of the model's torque energy in a set are checked


def torque_scale_suspects(pb, state) -> list[dict]:
    """``[{dataset, joint, gain, misfit, misfit_after_gain, offset, misfit_after_offset}]``: torque
    training sets' loaded joints (at least :data:`LOADED` of the predicted energy) whose measured
    torque is best matched by the model's times a gain beyond [1/:data:`GAIN_LIMIT`,
    :data:`GAIN_LIMIT`] that closes at least 1 - :data:`CLOSES` of the misfit (relative RMS, of the
    measured torque's RMS); ``offset`` [N m] is the constant that, added to the model's torque
    instead, matches it best, and ``misfit_after_offset`` what it leaves (:func:`scale_reason` names
    the better of the two)."""
    out = []
    for s in pb.ttrain:
        pred = T.predict(state.tfit, s)
        energy = np.sum(pred**2, axis=0)
        total = float(np.sum(energy))
        if not np.isfinite(total) or total <= 0:
            continue
        for j in range(pb.n):
            if energy[j] < LOADED * total or not np.isfinite(s.scale[j]):
                continue
            p, y = pred[:, j], s.tau[:, j]
            gain = float(p @ y / energy[j])
            norm = float(np.sqrt(np.mean(y**2))) or 1.0
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
