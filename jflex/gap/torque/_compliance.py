"""A joint's compliance seen in torque data: the link lagging its motor by the deflection
:func:`jflex.effects.compliance_deflection` of the torque it passes on, to first order along the
measured motion."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import jax
import numpy as np

from ..._dynamics import _rnea
from ..._sweep import flagged_vmap
from ...effects._measured_joint import compliance_deflection
from ...effects._registry import JOINT_FLEXIBILITY
from ...data._signal import motion_band, zero_phase_lowpass
from ._plausible import out_of_range
from ._set import CUTOFF_FACTOR, TorqueSet, TorqueTerm, on_rows

DEFLECTION_PLAUSIBLE = 0.05  # [rad] a transmission's deflection under the largest measured torque


# --- a joint's compliance, seen in torque data -----------------------------------------------------
def _jvp_row(robot, q, qd, qdd, dq, dqd, dqdd):
    # one direction per sample: forward mode through the traversal (the public rnea's analytic
    # derivative builds every direction's matrices, and compiles longer)
    f = lambda a, b, c: _rnea(robot, a, b, c, None, "rnea")
    return jax.jvp(f, (q, qd, qdd), (dq, dqd, dqdd))[1]


_jvp_batch = flagged_vmap(_jvp_row, in_axes=(None, 0, 0, 0, 0, 0, 0))  # checks as flags: see _torque._id_batch


def link_lag_column(s: TorqueSet, j: int, lag) -> np.ndarray:
    """(N, n) change of the rigid torques when the link of joint ``j`` lags the measured angle by
    ``lag`` (N,) per unit of it, to first order: minus RNEA's directional derivative along
    ``e_j (lag, d lag/dt, d2 lag/dt2)``."""
    lagd = np.gradient(lag, s.t)
    d = [np.zeros_like(s.q) for _ in range(3)]
    for k, v in enumerate((lag, lagd, np.gradient(lagd, s.t))):
        d[k][:, j] = v
    return -on_rows(_jvp_batch, (s.robot,), (s.q, s.qd, s.qdd, *d))


def smooth_torque(s: TorqueSet) -> np.ndarray:
    """The measured torque, low-passed (the set's own filter, else one at CUTOFF_FACTOR x the
    motion band): what a column built from the torque itself may differentiate."""
    if s.cutoff is not None:
        return s.tau
    if "smooth_tau" not in s.cache:
        h = float(np.mean(np.diff(s.t)))
        fc = min(CUTOFF_FACTOR * motion_band(s.q, h), 0.4 / h)
        s.cache["smooth_tau"] = zero_phase_lowpass(s.tau, h, fc)
    return s.cache["smooth_tau"]


def compliance_column(s: TorqueSet, j: int) -> np.ndarray:
    """(N, n) torque change per unit compliance ``1/k`` of a flexible joint ``j`` whose motor-side
    angle is what the encoder measured: the link lags it by the deflection ``tau_j / k`` (the
    measured joint torque, as the spring passes it on), so to first order in the compliance the
    rigid torques change by minus RNEA's directional derivative along ``e_j (tau_j, dtau_j/dt,
    d2tau_j/dt2)`` (the quasi-static deflection of :class:`jflex.effects.FlexibleJoints`; its own
    damping and the motor's inertia are left out: the latter is ``rotor_inertia``)."""
    key = ("compliance", j)
    if key not in s.cache:
        s.cache[key] = link_lag_column(s, j, compliance_deflection(smooth_torque(s)[:, j], 1.0))  # per unit compliance
    return s.cache[key]


@dataclasses.dataclass(frozen=True)
class CompliantJoint(TorqueTerm):
    """A flexible joint in torque data: the link lagging its motor by ``tau_j / k`` (:func:`compliance_column`)."""

    joint: int
    hyper: None = None
    effect: ClassVar[str] = JOINT_FLEXIBILITY
    signature: ClassVar[str] = "extra FRF peak / unmatched mode; in torques, the link lagging under load (tau_j / k)"

    def param_names(self):
        return ["compliance 1/k [rad/(N m)]"]

    def columns(self, s):
        return compliance_column(s, self.joint)[:, :, None]

    def implausible(self, theta, sets):
        return _compliance_implausible(float(theta[0]), self.joint, sets)


def _compliance_implausible(c, j, sets):
    tmax = max(float(np.abs(s.tau[:, j]).max()) for s in sets) if sets else 0.0
    return out_of_range("compliance 1/k", c, 0.0, DEFLECTION_PLAUSIBLE / max(tmax, 1e-12), "rad/(N m)",
                        f"a deflection of at most {DEFLECTION_PLAUSIBLE:g} rad under the largest measured torque")
