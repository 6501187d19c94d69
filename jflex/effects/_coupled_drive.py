"""A coupled drive: motors whose transmissions move two joints at once, as in the wrists of many
industrial arms (Staubli's TX and RX series: the last motor's shaft passes through joint 5, so
joint 5's motion turns joint 6's gear train).

With motor velocities ``w = K qd`` (joint-side units: ``K`` holds the coupling ratios, e.g.
``w_6 = qd_5 + qd_6``), each motor's inertia ``I_a`` and friction (viscous ``f_v``, Coulomb ``f_c``)
act on the motor shaft, and the virtual work ``w^T f`` gives the joint torques

$$ \\tau = K^T \\big(I_a K \\ddot q + f_v K \\dot q + f_c\\, \\mathrm{sign}(K \\dot q)\\big), $$

the coupled-joint terms of Gautier and Khalil's identification model (W. Khalil and E. Dombre,
"Modeling, Identification and Control of Robots", the coupled joints of a robot's wrist). The
inertia is written as the motors' kinetic energy ``1/2 w^T I_a w`` and the friction as a force,
so every analysis reads the law from the model; its diagonal parts (``I_a K_mj^2 qdd_j`` on joint
j) regroup with the joints' own rotor inertia and friction in identification.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import ParameterError, ShapeError
from ._base import Slots, joint_indices
from ._flexible_joint import _concrete
from ._linear import AbstractLinearEffect, CandidateInfo, DataScale, TORQUE_FRACTION, register_candidate
from ._registry import COUPLED_DRIVE

SMOOTH_SIGN = 5e-3  # [rad/s] width of a candidate's smooth sign (dry friction is sharp)
# coupling ratios a candidate tries: a motor row [1, c] on the joint pair (joint-side units; the
# ratio's magnitude is a design's gear ratio quotient, its sign the direction the shaft passes)
COUPLING_RATIOS = (-2.0, -1.0, -0.5, 0.5, 1.0, 2.0)


def _wrist_pairs(n):
    """Adjacent pairs among the last three joints: a coupled drive sits in a wrist, where the
    motors are moved back to the forearm and a shaft passes through the preceding joint (a motor
    coupling two base joints is not a design in use). Two placements keep the candidates, and
    the chances of a false alarm, few."""
    first = max(n - 3, 0)
    return tuple((j, j + 1) for j in range(first, n - 1))


def _candidate(joints, c):
    return CoupledDrive(joints, [[1.0, 1.0 if c is None else float(c)]], inertia=1.0, viscous=1.0, coulomb=1.0,
                        smoothing=SMOOTH_SIGN)


@register_candidate
class CoupledDrive(AbstractLinearEffect):
    """Motors driving the joints ``joints`` through the constant coupling matrix ``coupling``
    ``K`` (m, len(joints)): motor velocities ``K qd`` in joint-side units.

    **Arguments:** ``joints`` names (static); ``coupling`` (m, len(joints)); ``inertia`` I_a,
    ``viscous`` f_v, ``coulomb`` f_c (m,) or scalars, >= 0 [kg m^2, N m s/rad, N m];
    ``smoothing`` epsilon [rad/s] of the Coulomb law's smooth sign ``tanh(w / epsilon)``.
    """

    coupling: jnp.ndarray
    inertia: jnp.ndarray
    viscous: jnp.ndarray
    coulomb: jnp.ndarray
    smoothing: jnp.ndarray
    joints: tuple[str, ...] = eqx.field(static=True)

    linear_leaves = ("inertia", "viscous", "coulomb")
    units = ("kg m^2", "N m s/rad", "N m")
    candidate = CandidateInfo(
        name=COUPLED_DRIVE, build=_candidate, placements=_wrist_pairs, per_joint_law=False,
        signature="torque at one joint of a wrist pair following the other joint's motion",
        hyper=(COUPLING_RATIOS, "coupling ratio", 1.0), size=2)

    def __init__(self, joints, coupling, inertia=0.0, viscous=0.0, coulomb=0.0, smoothing=1e-3):
        self.joints = tuple(joints)
        K = jnp.asarray(coupling, dtype=float)
        if K.ndim != 2 or K.shape[1] != len(self.joints) or K.shape[0] == 0:
            raise ShapeError(f"CoupledDrive.coupling: expected (motors, {len(self.joints)}) for joints {self.joints}, got {K.shape}")
        Kc = _concrete(K)
        if Kc is not None and not np.all(np.isfinite(Kc)):
            raise ParameterError(f"CoupledDrive.coupling: must be finite, got {Kc.tolist()}")
        m = K.shape[0]

        def arr(v, name, strict=False):
            a = jnp.asarray(v, dtype=float)
            if a.ndim == 0:
                a = jnp.broadcast_to(a, (m,))
            if a.shape != (m,):
                raise ShapeError(f"CoupledDrive.{name}: expected a scalar or {m} values (one per motor), got shape {a.shape}")
            c = _concrete(a)
            if c is not None and (not np.all(np.isfinite(c)) or (np.any(c <= 0) if strict else np.any(c < 0))):
                raise ParameterError(f"CoupledDrive.{name} must be {'> 0' if strict else '>= 0'}, got {c.tolist()}")
            return a

        self.coupling = K
        self.inertia, self.viscous, self.coulomb = arr(inertia, "inertia"), arr(viscous, "viscous"), arr(coulomb, "coulomb")
        self.smoothing = arr(smoothing, "smoothing", strict=True)

    def _idx(self, robot):
        return jnp.array(joint_indices(robot, self.joints, "CoupledDrive"))

    def kinetic_energy(self, robot, slots: Slots, x, xd):
        w = self.coupling @ xd[self._idx(robot)]
        return 0.5 * jnp.sum(self.inertia * w**2)

    def _friction(self, robot, slots, xd, coulomb: bool):
        w = self.coupling @ xd[self._idx(robot)]
        fm = self.viscous * w + (self.coulomb * jnp.tanh(w / self.smoothing) if coulomb else 0.0)
        return jnp.zeros(slots.nx).at[self._idx(robot)].add(-(self.coupling.T @ fm))

    def generalized_force(self, robot, slots: Slots, t, x, xd, z):
        return self._friction(robot, slots, xd, True)

    def linear_force(self, robot, slots: Slots, t, x, xd, z):
        return self._friction(robot, slots, xd, False)  # dry friction sticks at rest

    def parameter_owners(self, robot):
        m = self.coupling.shape[0]
        pair = "+".join(self.joints)
        return tuple(f"{pair}:motor{i + 1}" for _ in self.linear_leaves for i in range(m))

    def parameter_joints(self, robot):
        first = joint_indices(robot, self.joints, "CoupledDrive")[0]
        return (first,) * (len(self.linear_leaves) * self.coupling.shape[0])

    def plausible_ranges(self, robot, scale: DataScale):
        # each motor's torque, passed on through K^T, at most TORQUE_FRACTION x the larger spread of
        # the joints it drives; the motor's rates estimated from the joints' (independent) spreads
        idx = list(joint_indices(robot, self.joints, "CoupledDrive"))
        K = np.abs(np.asarray(self.coupling))
        kmax = np.maximum(K.max(axis=1), 1e-12)
        t_std = TORQUE_FRACTION * float(np.max(scale.tau_std[idx])) / kmax
        t_rms = TORQUE_FRACTION * float(np.max(scale.tau_rms[idx])) / kmax
        wd = np.maximum(np.sqrt((K**2) @ (np.asarray(scale.qd_std)[idx] ** 2)), 1e-12)
        wdd = np.maximum(np.sqrt((K**2) @ (np.asarray(scale.qdd_std)[idx] ** 2)), 1e-12)
        return ([(0.0, float(v)) for v in t_std / wdd] + [(0.0, float(v)) for v in t_std / wd]
                + [(0.0, float(v)) for v in t_rms])
