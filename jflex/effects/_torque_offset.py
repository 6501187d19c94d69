"""A constant torque per joint: the offset of a torque sensor or of a motor current's zero."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import ParameterError, ShapeError
from ._base import Slots, joint_indices
from ._flexible_joint import _concrete
from ._linear import AbstractLinearEffect, CandidateInfo, DataScale, register_candidate, torque_bound
from ._registry import TORQUE_OFFSET


def _every_joint(n):
    return tuple((j,) for j in range(n))


@register_candidate
class TorqueOffset(AbstractLinearEffect):
    """A constant torque ``tau_0`` on each of ``joints``: what the measured torque reads when the
    joint transmits none (a strain gauge's or a current sensor's offset; a motor current's zero
    off by a few per cent of its range). The motors supply it: ``tau = tau_rigid + tau_0``.

    **Arguments:** ``joints`` names (static); ``offset`` (k,) or scalar [N m], any sign.
    """

    offset: jnp.ndarray
    joints: tuple[str, ...] = eqx.field(static=True)

    linear_leaves = ("offset",)
    units = ("N m",)
    candidate = CandidateInfo(
        name=TORQUE_OFFSET, build=lambda joints, hyper: TorqueOffset(joints, 1.0), placements=_every_joint,
        signature="a constant share of the residual at the joint", nonnegative=False)

    def __init__(self, joints, offset=0.0):
        self.joints = tuple(joints)
        a = jnp.asarray(offset, dtype=float)
        if a.ndim == 0:
            a = jnp.broadcast_to(a, (len(self.joints),))
        if a.shape != (len(self.joints),):
            raise ShapeError(f"TorqueOffset.offset: expected a scalar or {len(self.joints)} values (one per joint) [N m], got shape {a.shape}")
        v = _concrete(a)
        if v is not None and not np.all(np.isfinite(v)):
            raise ParameterError(f"TorqueOffset.offset must be finite [N m], got {v.tolist()}")
        self.offset = a

    def generalized_force(self, robot, slots: Slots, t, x, xd, z):
        idx = jnp.array(joint_indices(robot, self.joints, "TorqueOffset"))
        return jnp.zeros(slots.nx).at[idx].add(-self.offset)

    def linear_force(self, robot, slots: Slots, t, x, xd, z):
        return jnp.zeros(slots.nx)  # a constant: no stiffness, no damping

    def plausible_ranges(self, robot, scale: DataScale):
        # an offset cannot exceed the torque it is part of: bounded by the measured (or modelled) root mean square
        b = torque_bound(scale, joint_indices(robot, self.joints, "TorqueOffset"), rms=True)
        return [(-float(x), float(x)) for x in b]
