"""Gravity compensators acting on one joint (Eqs. 2.9-2.11 of the thesis "Posture Dependent Dynamics in Robotic Machining").

Both are conservative: they are written as a potential energy, so the torque they exert enters
every analysis through the Lagrange assembly, and their stiffness ``-d tau_GC / dq`` enters the
linearised stiffness K0 automatically.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import ParameterError, ShapeError
from ._base import AbstractEffect, Slots, joint_indices
from ._flexible_joint import _concrete


def _joint_index(robot, joint) -> int:
    return joint_indices(robot, (joint,), "gravity compensator")[0]


class FourierGravityCompensator(AbstractEffect):
    """Compensator torque as a Fourier series of the joint angle (the thesis' Eq. 2.11: the cosines),
    ``tau_GC = sum_k B_k cos(k q_j) + A_k sin(k q_j)``, applied to joint ``joint`` as an external
    torque.

    **Fields:** ``coefficients`` (m,) B_1..B_m [N m]; ``sine`` (m,) A_1..A_m [N m] (default zeros:
    the thesis' cosine series, a balancer whose zero lies at q_j = 0); ``joint`` (static) index or name.

    Its potential is ``V = -sum_k (B_k sin(k q_j) - A_k cos(k q_j)) / k``.
    """

    coefficients: jnp.ndarray
    sine: jnp.ndarray
    joint: int | str = eqx.field(static=True)

    def __init__(self, coefficients, joint=1, sine=None):
        c = jnp.asarray(coefficients, dtype=float)
        if c.ndim != 1 or c.shape[0] == 0:
            raise ShapeError(f"FourierGravityCompensator.coefficients: expected (m,) with m >= 1 [N m], got {c.shape}")
        s = jnp.zeros_like(c) if sine is None else jnp.asarray(sine, dtype=float)
        if s.shape != c.shape:
            raise ShapeError(f"FourierGravityCompensator.sine: expected {c.shape} (as coefficients) [N m], got {s.shape}")
        for name, v in (("coefficients", c), ("sine", s)):
            cv = _concrete(v)
            if cv is not None and not np.all(np.isfinite(cv)):
                raise ParameterError(f"FourierGravityCompensator.{name}: contains NaN or inf")
        self.coefficients = c
        self.sine = s
        self.joint = joint

    def potential_energy(self, robot, slots: Slots, x):
        q = x[_joint_index(robot, self.joint)]
        k = jnp.arange(1, self.coefficients.shape[0] + 1, dtype=x.dtype)
        return -jnp.sum((self.coefficients * jnp.sin(k * q) - self.sine * jnp.cos(k * q)) / k)


class SpringGravityCompensator(AbstractEffect):
    """Linear-spring compensator (the thesis' Eq. 2.9, Fig. 2.4): a spring of stiffness ``k_c``
    and free length ``x0`` between point A (distance ``L`` from the joint axis on the previous
    link) and point B (distance ``r`` on the link), with ``gamma = offset - q_j`` the angle
    between O A and O B (``offset = pi/2`` gives Eq. 2.10).

    Potential ``V = k_c (l - x0)^2 / 2``, ``l = sqrt(L^2 + r^2 - 2 L r cos gamma)``; the torque
    on the joint is ``L k_c r sin(gamma) (1 - x0 / l)`` (Eq. 2.9).

    **Fields:** ``spring_stiffness`` k_c [N/m], ``L`` [m], ``r`` [m], ``free_length`` x0 [m],
    ``offset`` [rad]; ``joint`` (static).
    """

    spring_stiffness: jnp.ndarray
    L: jnp.ndarray
    r: jnp.ndarray
    free_length: jnp.ndarray
    offset: jnp.ndarray
    joint: int | str = eqx.field(static=True)

    def __init__(self, spring_stiffness, L, r, free_length, *, joint=1, offset=np.pi / 2):
        vals = dict(spring_stiffness=spring_stiffness, L=L, r=r, free_length=free_length)
        for name, v in vals.items():
            a = np.asarray(v, dtype=float)
            if a.shape != () or not np.isfinite(a) or (a <= 0 if name != "free_length" else a < 0):
                raise ParameterError(f"SpringGravityCompensator.{name}: expected a positive finite number, got {v}")
        self.spring_stiffness = jnp.asarray(spring_stiffness, dtype=float)
        self.L = jnp.asarray(L, dtype=float)
        self.r = jnp.asarray(r, dtype=float)
        self.free_length = jnp.asarray(free_length, dtype=float)
        self.offset = jnp.asarray(offset, dtype=float)
        self.joint = joint

    def potential_energy(self, robot, slots: Slots, x):
        gamma = self.offset - x[_joint_index(robot, self.joint)]
        length = jnp.sqrt(self.L**2 + self.r**2 - 2 * self.L * self.r * jnp.cos(gamma))
        return 0.5 * self.spring_stiffness * (length - self.free_length) ** 2
