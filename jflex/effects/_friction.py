"""Joint friction: viscous, Coulomb with a smooth sign, and Stribeck."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import ParameterError, ShapeError
from ._base import AbstractEffect, Slots, joint_indices


class JointFriction(AbstractEffect):
    """Friction torque on robot joints,

    $$ \\tau_f = -\\big[F_v \\dot q + (F_c + (F_s - F_c) e^{-(\\dot q / v_s)^2}) \\tanh(\\dot q / \\epsilon)\\big]. $$

    **Arguments:** ``joints`` names (static); ``viscous`` F_v, ``coulomb`` F_c, ``stribeck``
    F_s (breakaway, >= F_c; default F_c: no Stribeck effect) [N m s/rad, N m] (k,) or scalars;
    ``stribeck_velocity`` v_s [rad/s]; ``smoothing`` epsilon [rad/s]: the width of the smooth sign
    (a regularised Coulomb law; stiction is not modelled).
    """

    viscous: jnp.ndarray
    coulomb: jnp.ndarray
    stribeck: jnp.ndarray
    stribeck_velocity: jnp.ndarray
    smoothing: jnp.ndarray
    joints: tuple[str, ...] = eqx.field(static=True)

    def __init__(self, joints, viscous=0.0, coulomb=0.0, stribeck=None, stribeck_velocity=0.1, smoothing=1e-3):
        self.joints = tuple(joints)
        k = len(self.joints)

        def arr(v, name, strict=False):
            a = np.broadcast_to(np.asarray(v, dtype=float), (k,)).copy() if np.ndim(v) == 0 else np.asarray(v, dtype=float)
            if a.shape != (k,):
                raise ShapeError(f"JointFriction.{name}: expected a scalar or {k} values (one per joint), got shape {a.shape}")
            if not np.all(np.isfinite(a)) or (np.any(a <= 0) if strict else np.any(a < 0)):
                raise ParameterError(f"JointFriction.{name} must be {'> 0' if strict else '>= 0'}, got {a.tolist()}")
            return jnp.asarray(a)

        self.viscous = arr(viscous, "viscous")
        self.coulomb = arr(coulomb, "coulomb")
        self.stribeck = arr(coulomb if stribeck is None else stribeck, "stribeck")
        self.stribeck_velocity = arr(stribeck_velocity, "stribeck_velocity", strict=True)
        self.smoothing = arr(smoothing, "smoothing", strict=True)

    def _idx(self, robot):
        return jnp.array(joint_indices(robot, self.joints, "JointFriction"))

    def torque(self, qd):
        """Friction torque (k,) [N m] at joint rates ``qd`` (k,) [rad/s] (sign: resisting)."""
        level = self.coulomb + (self.stribeck - self.coulomb) * jnp.exp(-((qd / self.stribeck_velocity) ** 2))
        return -(self.viscous * qd + level * jnp.tanh(qd / self.smoothing))

    def generalized_force(self, robot, slots: Slots, t, x, xd, z):
        idx = self._idx(robot)
        return jnp.zeros(slots.nx).at[idx].add(self.torque(xd[idx]))
