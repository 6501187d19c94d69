"""Joint friction: viscous, Coulomb with a smooth sign, and Stribeck."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import ParameterError, ShapeError
from ._base import AbstractEffect, Slots, joint_indices
from ._flexible_joint import _concrete
from ._linear import AbstractLinearEffect, CandidateInfo, DataScale, register_candidate, torque_bound
from ._registry import ASYMMETRIC_COULOMB, COULOMB_FRICTION


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


SMOOTH_SIGN = 5e-3  # [rad/s] width of the smooth sign of a candidate's Coulomb law (dry friction is sharp)


def _every_joint(n):
    return tuple((j,) for j in range(n))


@register_candidate
class AsymmetricCoulomb(AbstractLinearEffect):
    """Coulomb friction with different levels in the two directions of motion,

    $$ \\tau_f = -\\big[F_c^+ s^+(\\dot q) - F_c^- s^-(\\dot q)\\big], \\qquad
       s^\\pm = \\tfrac12 (1 \\pm \\tanh(\\dot q / \\epsilon)), $$

    the smooth sign of :class:`JointFriction` split by direction (a seal or a preloaded bearing
    that drags more one way; a gravity-loaded gear whose tooth faces differ). Equal levels give
    :class:`JointFriction`'s Coulomb term; unequal ones equal a symmetric level plus a constant,
    ``(F_c^+ - F_c^-)/2``, which is why identification groups it with a torque offset.

    **Arguments:** ``joints`` names (static); ``positive`` F_c+, ``negative`` F_c- [N m] (k,) or
    scalars, >= 0; ``smoothing`` epsilon [rad/s] > 0.
    """

    positive: jnp.ndarray
    negative: jnp.ndarray
    smoothing: jnp.ndarray
    joints: tuple[str, ...] = eqx.field(static=True)

    linear_leaves = ("positive", "negative")
    units = ("N m", "N m")
    candidate = CandidateInfo(
        name=ASYMMETRIC_COULOMB, build=lambda joints, hyper: AsymmetricCoulomb(joints, 1.0, 1.0, SMOOTH_SIGN),
        placements=_every_joint, signature="sign of velocity, a different level in each direction",
        # beside a nominal symmetric Coulomb law it adds a constant alone: the torque offset's candidate
        subsumed_by=COULOMB_FRICTION)

    def __init__(self, joints, positive=0.0, negative=0.0, smoothing=1e-3):
        self.joints = tuple(joints)
        k = len(self.joints)

        def arr(v, name, strict=False):
            a = jnp.asarray(v, dtype=float)
            if a.ndim == 0:
                a = jnp.broadcast_to(a, (k,))
            if a.shape != (k,):
                raise ShapeError(f"AsymmetricCoulomb.{name}: expected a scalar or {k} values (one per joint), got shape {a.shape}")
            c = _concrete(a)
            if c is not None and (not np.all(np.isfinite(c)) or (np.any(c <= 0) if strict else np.any(c < 0))):
                raise ParameterError(f"AsymmetricCoulomb.{name} must be {'> 0' if strict else '>= 0'}, got {c.tolist()}")
            return a

        self.positive = arr(positive, "positive")
        self.negative = arr(negative, "negative")
        self.smoothing = arr(smoothing, "smoothing", strict=True)

    def generalized_force(self, robot, slots: Slots, t, x, xd, z):
        idx = jnp.array(joint_indices(robot, self.joints, "AsymmetricCoulomb"))
        s = jnp.tanh(xd[idx] / self.smoothing)
        return jnp.zeros(slots.nx).at[idx].add(-(self.positive * 0.5 * (1 + s) - self.negative * 0.5 * (1 - s)))

    def linear_force(self, robot, slots: Slots, t, x, xd, z):
        return jnp.zeros(slots.nx)  # dry friction sticks at rest (see AbstractEffect.linear_force)

    def plausible_ranges(self, robot, scale: DataScale):
        b = torque_bound(scale, joint_indices(robot, self.joints, "AsymmetricCoulomb"), rms=True)
        return [(0.0, float(x)) for x in b] * 2
