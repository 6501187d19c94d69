"""Laws between a joint's measurement and its rigid motion: a transmission's compliance, play in a
gear, a sensor's delay and a drive's gain. Each relates what a sensor or a drive reads to what the
rigid links do; added to a :class:`jflex.Model` they leave its equations of motion as they are
(DriveGain scales the actuation) and give the relation as methods on measured signals, the form
in which the gap diagnosis fits them along a measured motion.

The laws are NumPy functions, written once here (a delayed sensor's shift is the data layer's
:func:`jflex.data._signal.shift`): the diagnosis' candidate columns call them.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import ParameterError
# a sensor delayed by d reads the signal shifted by the data layer's shift operator S_d (linear
# interpolation; the samples left without data hold the record's first or last value)
from ..data._signal import shift as delayed
from ._base import AbstractEffect, Slots, joint_indices
from ._flexible_joint import _concrete


# --- the laws --------------------------------------------------------------------------------------
def compliance_deflection(tau, compliance):
    """Deflection [rad] of a transmission of compliance ``1/k`` [rad/(N m)] passing the torque
    ``tau`` [N m]: the link lags its motor by ``tau / k`` (the quasi-static deflection of
    :class:`jflex.effects.FlexibleJoints`)."""
    return tau * compliance


def play(x, b):
    """Play (backlash) operator of half-width ``b``: the driven side stays put until the driving
    side has crossed the gap."""
    y = np.empty_like(x)
    y[0] = x[0]
    for i in range(1, len(x)):
        y[i] = min(max(y[i - 1], x[i] - b), x[i] + b)
    return y


def loaded_play_side(tau, width):
    """The side of the play a loaded gear sits on, ``sgn(tau)`` smoothed as ``tanh(tau / (width
    std(tau)))``: the transmitted torque presses the link against one tooth face, and it crosses
    the play when that torque changes sign (over a duration unknown, hence ``width``)."""
    return np.tanh(tau / (width * max(float(np.std(tau)), 1e-300)))


def first_order_zero_phase(x, t, tau):
    """First-order low-pass run forwards and backwards (no lag), time constant ``tau`` [s]: the
    engagement of gear teeth meeting through a contact compliance."""
    import scipy.signal as ss

    a = np.exp(-np.mean(np.diff(t)) / tau)
    return ss.filtfilt([1 - a], [1, -a], np.asarray(x, float), padtype="constant", padlen=0) if len(x) > 6 else np.asarray(x)


def scaled_torque(tau, gain):
    """The torque a drive of ``gain`` delivers (or a sensor of that gain reads) for ``tau``: a motor
    current converted with a data-sheet torque constant, a gear's efficiency, a gauge's calibration
    (M. Gautier and S. Briot, "Global identification of joint drive gains and dynamic parameters
    of robots")."""
    return gain * tau


# --- the effects -----------------------------------------------------------------------------------
def _per_joint(name, joints, value, lo=None):
    a = jnp.broadcast_to(jnp.asarray(value, dtype=float), (len(joints),))
    v = _concrete(a)
    if v is not None and (not np.all(np.isfinite(v)) or (lo is not None and np.any(v < lo))):
        bound = "" if lo is None else f" and >= {lo:g}"
        raise ParameterError(f"{name} must be finite{bound}, got {np.asarray(v).tolist()}")
    return a


class _MeasuredJoints(AbstractEffect):
    joints: tuple[str, ...] = eqx.field(static=True)

    def _idx(self, robot):
        return list(joint_indices(robot, self.joints, type(self).__name__))


class JointCompliance(_MeasuredJoints):
    """A transmission's compliance at each of ``joints``: the link lags the motor-side angle an
    encoder reads by :func:`compliance_deflection` of the torque it passes on. The stiff limit of
    :class:`jflex.effects.FlexibleJoints` (no rotor dynamics between motor and link).

    **Arguments:** ``joints`` names (static); ``compliance`` (k,) or scalar ``1/k`` [rad/(N m)], >= 0.
    """

    compliance: jnp.ndarray

    def __init__(self, joints, compliance):
        self.joints = tuple(joints)
        self.compliance = _per_joint("JointCompliance.compliance [rad/(N m)]", self.joints, compliance, 0.0)

    def deflection(self, robot, tau):
        """Deflection (N, n) [rad] of the joints under the joint torques ``tau`` (N, n); zero elsewhere."""
        tau = np.asarray(tau, float)
        out = np.zeros_like(tau)
        idx = self._idx(robot)
        out[:, idx] = compliance_deflection(tau[:, idx], np.asarray(self.compliance))
        return out

    def link_angles(self, robot, q_motor, tau):
        """The link angles (N, n) behind the motor-side angles ``q_motor`` under the torques ``tau``."""
        return np.asarray(q_motor, float) - self.deflection(robot, tau)


class Backlash(_MeasuredJoints):
    """Play of half-width ``b`` in the gear of each of ``joints``: the link stays put until the
    motor side has crossed the gap (:func:`play`); a gear loaded by gravity or inertia sits on the
    face its torque presses (:func:`loaded_play_side`).

    **Arguments:** ``joints`` names (static); ``half_width`` (k,) or scalar ``b`` [rad], >= 0.
    """

    half_width: jnp.ndarray

    def __init__(self, joints, half_width):
        self.joints = tuple(joints)
        self.half_width = _per_joint("Backlash.half_width [rad]", self.joints, half_width, 0.0)

    def link_angles(self, robot, q_motor):
        """The link angles (N, n) a motor-side motion ``q_motor`` (N, n) drives through the play."""
        q = np.array(q_motor, float)
        for j, b in zip(self._idx(robot), np.asarray(self.half_width)):
            q[:, j] = play(q[:, j], float(b))
        return q

    def loaded_link_angles(self, robot, q_motor, tau, width=0.01):
        """The link angles of a loaded gear: the motor-side angles less ``b`` on the side the joint
        torque ``tau`` (N, n) presses (:func:`loaded_play_side`)."""
        q = np.array(q_motor, float)
        for j, b in zip(self._idx(robot), np.asarray(self.half_width)):
            q[:, j] = q[:, j] - float(b) * loaded_play_side(np.asarray(tau, float)[:, j], width)
        return q


class SensorDelay(AbstractEffect):
    """A measured channel read ``delay`` [s] late (negative: early): a bus's latency, a time stamp
    taken at the end of a cycle. It acts on measurements, not on the motion: its torque is zero;
    :meth:`apply` gives the signal as the sensor reads it (:func:`delayed`).

    **Arguments:** ``delay`` [s], a scalar of either sign.
    """

    delay: float = eqx.field(static=True)

    def __init__(self, delay):
        d = float(delay)
        if not np.isfinite(d):
            raise ParameterError(f"SensorDelay.delay must be finite [s], got {d}")
        self.delay = d

    def apply(self, t, x):
        """The signal ``x`` (N, ...) sampled at ``t`` (N,) as the delayed sensor reads it."""
        return delayed(np.asarray(x, float), np.asarray(t, float), self.delay)


class DriveGain(_MeasuredJoints):
    """The drive of each of ``joints`` delivers ``gain`` times the torque commanded
    (:func:`scaled_torque`): the input matrix's column of the joint scales, so a command ``u`` gives
    the generalised force ``gain u`` and the command a motion needs is ``tau / gain``.

    **Arguments:** ``joints`` names (static); ``gain`` (k,) or scalar, > 0.
    """

    gain: jnp.ndarray

    def __init__(self, joints, gain=1.0):
        self.joints = tuple(joints)
        self.gain = _per_joint("DriveGain.gain", self.joints, gain)
        v = _concrete(self.gain)
        if v is not None and np.any(v <= 0):
            raise ParameterError(f"DriveGain.gain must be > 0, got {np.asarray(v).tolist()}")

    def actuation(self, robot, slots: Slots, B):
        idx = jnp.array(self._idx(robot))
        return B.at[:, idx].set(scaled_torque(B[:, idx], self.gain[None, :]))

    def command(self, robot, tau):
        """The command (N, n) or (n,) the drives need for the joint torques ``tau``."""
        tau = np.array(tau, float)
        idx = self._idx(robot)
        tau[..., idx] = tau[..., idx] / np.asarray(self.gain)
        return tau
