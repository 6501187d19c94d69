"""A sensor's delay seen in torque data: no coefficient, the shift of the measurement
(:func:`jflex.effects.delayed`) searched on a grid."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from ...effects._registry import SENSOR_DELAY
from ._plausible import out_of_range
from ._set import TorqueTerm, fit_terms, predict

# [s] grid of sensor delays, of either sign: the torque lagging the angles (d > 0), or the encoders
# lagging the torque (d < 0: a position read by a slower bus, or stamped at the end of a cycle)
DELAYS = tuple(np.round(np.concatenate([np.arange(0.001, 0.0605, 0.001), -np.arange(0.001, 0.0605, 0.001)]), 4))
DELAY_PLAUSIBLE = 0.05  # [s] a sensor's delay is a few samples to tens of milliseconds


@dataclasses.dataclass(frozen=True)
class SensorDelay(TorqueTerm):
    """The torque measurement lagging the motion by ``hyper`` [s] (negative: the angles lag the
    torque): no coefficient, the fit's ``delay`` (the shift operator of :func:`._torque.fit_terms`),
    searched on :data:`DELAYS`."""

    joint: None = None
    hyper: float | None = None
    effect: ClassVar[str] = SENSOR_DELAY
    per_joint: ClassVar[bool] = False
    signature: ClassVar[str] = "phase lag: correlation with d tau/dt"

    def param_names(self):
        return []

    def columns(self, s):
        return np.zeros(s.q.shape + (0,))

    @property
    def delay(self):
        return self.hyper

    def parameters(self, theta):
        return {"delay [s]": float(self.hyper)}

    def implausible(self, theta, sets):
        return out_of_range("delay", float(self.hyper), -DELAY_PLAUSIBLE, DELAY_PLAUSIBLE, "s",
                            "a sensor's delay is a few samples to tens of milliseconds")

    def search(self, base_terms, base_delay, sets, inertia=None):
        base = tuple(t for t in base_terms if not isinstance(t, SensorDelay))  # one delay, refitted from scratch
        best = min((fit_terms(base, d, sets, inertia) for d in DELAYS), key=lambda f: f.cost)
        return dataclasses.replace(best, terms=best.terms + (SensorDelay(None, best.delay),))

    def signature_columns(self, s, fit):
        return (np.gradient(predict(fit, s), s.t, axis=0))[:, :, None]
