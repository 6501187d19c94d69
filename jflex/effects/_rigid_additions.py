"""Rigid additions to the robot: the reflected inertia of a joint's rotor, and a payload carried by
a link. Both change the mass the joints move and nothing else."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import ParameterError, ShapeError
from ._base import AbstractEffect, Slots, joint_indices
from ._flexible_joint import _concrete


class RotorInertia(AbstractEffect):
    """Reflected rotor inertia ``I_a`` of rigidly geared motors: kinetic energy
    ``T = 1/2 sum_j I_a,j qd_j^2`` (the gyroscopic coupling of a rotor on a moving link is left
    out, as in Spong's reduced model).

    **Arguments:** ``joints`` names (static); ``inertia`` (k,) or scalar [kg m^2], >= 0.
    """

    inertia: jnp.ndarray
    joints: tuple[str, ...] = eqx.field(static=True)

    def __init__(self, joints, inertia):
        self.joints = tuple(joints)
        a = jnp.broadcast_to(jnp.asarray(inertia, dtype=float), (len(self.joints),))
        v = _concrete(a)
        if v is not None and (not np.all(np.isfinite(v)) or np.any(v < 0)):
            raise ParameterError(f"RotorInertia.inertia must be finite and >= 0 [kg m^2], got {np.asarray(v).tolist()}")
        self.inertia = a

    def _idx(self, robot):
        return jnp.array(joint_indices(robot, self.joints, "RotorInertia"))

    def kinetic_energy(self, robot, slots: Slots, x, xd):
        return 0.5 * jnp.sum(self.inertia * xd[self._idx(robot)] ** 2)


class Payload(AbstractEffect):
    """A rigid payload on a link: its inertial parameters (Pinocchio's order ``[m, m c, I about the
    link frame's origin]``) added to the link's.

    **Arguments:** ``parameters`` (10,); ``link`` name (static; default: the last link).
    """

    parameters: jnp.ndarray
    link: str | None = eqx.field(static=True)

    def __init__(self, parameters, link=None):
        p = jnp.asarray(parameters, dtype=float)
        if p.shape != (10,):
            raise ShapeError(f"Payload.parameters: expected (10,) [m, m c_x, m c_y, m c_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz], got {p.shape}")
        v = _concrete(p)
        if v is not None and not np.all(np.isfinite(v)):
            raise ParameterError("Payload.parameters: contains NaN or inf")
        self.parameters = p
        self.link = link

    def modify_robot(self, robot):
        i = robot.nq - 1 if self.link is None else list(robot.link_names).index(self.link)
        return robot.replace(inertia=jnp.asarray(robot.inertia).at[i].add(self.parameters))
