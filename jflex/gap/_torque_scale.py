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
    """``[{dataset, joint, gain, misfit, misfit_after_gain}]``: torque training sets' loaded joints
    (at least :data:`LOADED` of the predicted energy) whose measured torque is best matched by
    the model's times a gain beyond [1/:data:`GAIN_LIMIT`, :data:`GAIN_LIMIT`] that closes at
    least 1 - :data:`CLOSES` of the misfit (relative RMS, of the measured torque's RMS)."""
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
                out.append(dict(dataset=s.name, joint=pb.names[j], gain=gain, misfit=before, misfit_after_gain=after))
    return out


def scale_reason(suspects: list[dict]) -> str:
    """The stop reason for a case whose torques look off scale."""
    joints = ", ".join(f"{d['joint']} in {d['dataset']} ({d['gain']:.3g} x)" for d in suspects)
    return ("the measured torques look off scale: the model's torque times a constant matches them far better "
            f"than the model itself ({joints}); a unit, a gear ratio or a current-to-torque constant (case.yaml: "
            "the torque columns' scale) is likely wrong, and no effect is named until it is fixed")
