"""A linear spring on chosen coordinates of a model, with a damping law.

The elastic element the frequency-side analyses place where a model is compliant: a joint the rigid
model holds stiff, or the virtual joints of a bearing's tilt or a link's lumped bending. Its potential
energy is ``1/2 e^T K e`` on the coordinates ``e``; its loss is the damping law's
(:class:`~jflex.effects.KelvinVoigt`, :class:`~jflex.effects.Hysteretic`,
:class:`~jflex.effects.Fractional`, or a user's :class:`~jflex.effects.AbstractDampingLaw`), acting
through the same stiffness as :class:`~jflex.effects.StructuralDamping` does.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import ParameterError, ShapeError
from ._base import AbstractEffect, Slots, joint_indices
from ._flexible_joint import _concrete
from ._damping import AbstractDampingLaw


class Spring(AbstractEffect):
    """Linear spring ``1/2 e^T K e`` plus a damping law on the coordinates ``coords``.

    **Arguments:** ``coords``: names of the rigid robot's joints (or indices into ``x``), static;
    ``stiffness``: (m,) or (m, m) symmetric positive-definite [N m/rad or N/m]; ``law``: an
    :class:`AbstractDampingLaw` or None (no loss); ``name`` prefixes the law's state names.
    """

    stiffness: jnp.ndarray
    law: AbstractDampingLaw | None
    coords: tuple = eqx.field(static=True)
    name: str = eqx.field(static=True, default="spring")

    def __init__(self, coords, stiffness, law=None, name: str = "spring"):
        self.coords = tuple(c if isinstance(c, str) else int(c) for c in coords)
        m = len(self.coords)
        K = jnp.asarray(stiffness, dtype=float)
        if K.shape == (m,):
            K = jnp.diag(K)
        if K.shape != (m, m):
            raise ShapeError(f"Spring.stiffness: expected ({m},) or ({m}, {m}) for coords {self.coords}, got {K.shape}")
        Kn = _concrete(K)
        if Kn is not None and (not np.all(np.isfinite(Kn)) or not np.allclose(Kn, Kn.T)
                               or np.linalg.eigvalsh(0.5 * (Kn + Kn.T)).min() <= 0):
            raise ParameterError(f"Spring.stiffness: must be finite, symmetric and positive definite [N m/rad], got {Kn.tolist()}")
        if law is not None and not isinstance(law, AbstractDampingLaw):
            raise ParameterError(f"Spring.law: expected a jflex.effects damping law or None, got {type(law).__name__}")
        self.stiffness, self.law, self.name = K, law, name

    def _idx(self, robot):
        return jnp.array(joint_indices(robot, self.coords, "Spring"), dtype=int)

    def state_names(self, robot):
        if self.law is None:
            return ()
        m = len(self.coords)
        return tuple(f"{self.name}.{s}" for s in self.law.state_suffixes(m, m))

    def initial_state(self, robot, slots: Slots):
        m = len(self.coords)
        return jnp.zeros(0) if self.law is None else self.law.initial_state(m, m)

    def potential_energy(self, robot, slots: Slots, x):
        e = x[self._idx(robot)]
        return 0.5 * e @ (self.stiffness @ e)

    def generalized_force(self, robot, slots: Slots, t, x, xd, z):
        if self.law is None:
            return jnp.zeros(slots.nx)
        idx = self._idx(robot)
        F = self.law.force(self.stiffness, x[idx], xd[idx], z[slots.states], jnp.eye(len(self.coords)))
        return jnp.zeros(slots.nx, dtype=F.dtype).at[idx].add(-F)

    def state_rate(self, robot, slots: Slots, t, x, xd, z):
        if self.law is None:
            return jnp.zeros(0)
        idx = self._idx(robot)
        return self.law.state_rate(self.stiffness, x[idx], xd[idx], z[slots.states], jnp.eye(len(self.coords)))

    def dynamic_stiffness(self, robot, slots: Slots, x0, omega):
        if self.law is None:
            return None
        D = self.law.frequency_term(self.stiffness, omega, jnp.eye(len(self.coords)))
        if D is None:
            return None
        idx = self._idx(robot)
        return jnp.zeros((slots.nx, slots.nx), complex).at[jnp.ix_(idx, idx)].add(D)
