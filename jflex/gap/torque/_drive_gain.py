"""A drive's gain seen in torque data: the torque read at a joint a constant factor off what the
joint transmits (:func:`jflex.effects.scaled_torque`)."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from ...effects._measured_joint import scaled_torque
from ...effects._registry import DRIVE_GAIN
from ._plausible import out_of_range
from ._set import TorqueTerm, term_columns, weighted_inertia_columns

GAIN_PLAUSIBLE = 0.3  # |gain - 1|: a data-sheet torque constant, a gear's efficiency, a gauge's calibration
# are off by per cents to tens of per cents; a torque several times off is a scale error of the data
# (:mod:`._torque_scale`), not a drive


@dataclasses.dataclass(frozen=True)
class DriveGain(TorqueTerm):
    """The torque read at ``joint`` is ``1 + gamma`` times what the joint transmits: a motor
    current converted with a data-sheet torque constant, a gear whose efficiency the ratio leaves
    out, a torque sensor's calibration (the joint drive gains of M. Gautier and S. Briot, "Global
    identification of joint drive gains and dynamic parameters of robots"). Column: the nominal
    model's rigid torque at the joint, coefficient ``gamma``. With the inertial parameters refitted
    only a gain relative to the other joints shows (every torque times one factor is a scaled
    robot); a known mass on the robot fixes the absolute one."""

    joint: int
    hyper: None = None
    effect: ClassVar[str] = DRIVE_GAIN
    signature: ClassVar[str] = "the joint's torque larger or smaller by a constant factor"

    def param_names(self):
        return ["gain - 1"]

    def bounds(self):
        return [-np.inf], [np.inf]

    def columns(self, s):
        out = np.zeros(s.q.shape + (1,))
        out[:, self.joint, 0] = scaled_torque(s.F0[:, self.joint], 1.0)  # the law's derivative in the gain
        return out

    def signature_columns(self, s, fit):
        # the column is the model's own torque, most of which the inertial refit absorbs (a heavier
        # link raises it too): what a residual can show of a gain is the part no inertial change makes
        col = term_columns(self, s)
        if fit is None or fit.delta is None:
            return col
        ok = np.isfinite(s.scale)
        w = np.where(ok, 1.0 / np.where(ok, s.scale, 1.0), 0.0)
        Yw, _ = weighted_inertia_columns(s)
        x = (col[:, :, 0] * w[None, :]).ravel()
        perp = x - Yw @ np.linalg.lstsq(Yw, x, rcond=1e-10)[0]
        return (perp.reshape(col.shape[:2]) * np.where(ok, s.scale, 0.0)[None, :])[:, :, None]

    def implausible(self, theta, sets):
        return out_of_range("drive gain - 1", float(theta[0]), -GAIN_PLAUSIBLE, GAIN_PLAUSIBLE, "",
                            "a torque constant or a gear's efficiency is off by tens of per cents at most")
