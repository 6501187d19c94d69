"""The identification regressor: rigid inertial parameters plus the joint-level terms that
torque data also see (viscous and Coulomb friction, rotor armature, gravity-compensator Fourier
terms, seed 003 Eqs. 2.11/3.1 and Appendix B).

Parameters are ordered ``[pi_1 (10), ..., pi_n (10), Fv (n), Fc (n), Ia (n), B_1..B_K]``, each
group present only when switched on; ``pi_i`` in Pinocchio's order.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._dynamics import regressor as rigid_regressor
from .._robot import Robot

_PI_NAMES = ("m", "mcx", "mcy", "mcz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")


class Regressor(eqx.Module):
    """Which terms the torque model has; ``__call__`` gives the (n, p) regressor of one sample.

    **Fields (static):**

    - ``viscous``, ``coulomb``: per-joint ``Fv qd`` and ``Fc sign(qd)`` friction.
    - ``armature``: per-joint rotor inertia reflected to the joint, ``Ia qdd``.
    - ``compensator``: ``(joint, K)``: a gravity compensator on ``joint`` (0-based) modelled by
      ``tau_GC = sum_k B_k cos(k q_joint)`` acting as an external torque (Eq. 2.11), so its
      columns are ``-cos(k q)``; ``None`` for none.
    - ``coulomb_width`` [rad/s]: when > 0, ``sign`` is replaced by ``tanh(qd / width)``.
    """

    viscous: bool = eqx.field(static=True, default=True)
    coulomb: bool = eqx.field(static=True, default=True)
    armature: bool = eqx.field(static=True, default=False)
    compensator: tuple[int, int] | None = eqx.field(static=True, default=None)
    coulomb_width: float = eqx.field(static=True, default=0.0)

    def n_params(self, n: int) -> int:
        """Number of standard parameters for an ``n``-joint robot."""
        k = self.compensator[1] if self.compensator else 0
        return 10 * n + n * (int(self.viscous) + int(self.coulomb) + int(self.armature)) + k

    def names(self, robot: Robot) -> tuple[str, ...]:
        """Parameter names, e.g. ``link2.mcx``, ``joint1.Fv``, ``joint2.B3``."""
        out = [f"{l}.{p}" for l in robot.link_names for p in _PI_NAMES]
        for flag, tag in ((self.viscous, "Fv"), (self.coulomb, "Fc"), (self.armature, "Ia")):
            if flag:
                out += [f"{j}.{tag}" for j in robot.joint_names]
        if self.compensator:
            j, k = self.compensator
            out += [f"{robot.joint_names[j]}.B{i + 1}" for i in range(k)]
        return tuple(out)

    def vector(self, robot: Robot, *, fv=None, fc=None, armature=None, compensator=None):
        """The standard parameter vector (p,) of ``robot`` with the given joint-level terms
        (zeros where not given)."""
        n = robot.nq
        parts = [jnp.ravel(robot.inertia)]
        for flag, v in ((self.viscous, fv), (self.coulomb, fc), (self.armature, armature)):
            if flag:
                parts.append(jnp.zeros(n) if v is None else jnp.asarray(v, dtype=float).reshape(n))
        if self.compensator:
            k = self.compensator[1]
            parts.append(jnp.zeros(k) if compensator is None else jnp.asarray(compensator, dtype=float).reshape(k))
        return jnp.concatenate(parts)

    def __call__(self, robot: Robot, q, qd, qdd):
        """Regressor Y (n, p) of one sample: ``tau = Y @ theta``.

        **Arguments:** ``q``, ``qd``, ``qdd`` (n,) [rad, rad/s, rad/s^2].
        """
        n = robot.nq
        cols = [rigid_regressor(robot, q, qd, qdd)]
        eye = jnp.eye(n, dtype=cols[0].dtype)
        if self.viscous:
            cols.append(eye * qd)
        if self.coulomb:
            s = jnp.tanh(qd / self.coulomb_width) if self.coulomb_width > 0 else jnp.sign(qd)
            cols.append(eye * s)
        if self.armature:
            cols.append(eye * qdd)
        if self.compensator:
            j, k = self.compensator
            c = -jnp.cos(jnp.arange(1, k + 1) * q[j])
            cols.append(jnp.zeros((n, k), dtype=cols[0].dtype).at[j].set(c))
        return jnp.concatenate(cols, axis=1)

    def stack(self, robot: Robot, q, qd, qdd):
        """Observation matrix A (N n, p) of N samples, rows sample-major (``tau.ravel()`` order).

        **Arguments:** ``q``, ``qd``, ``qdd`` (N, n).
        """
        return _stack(self, robot, jnp.asarray(q), jnp.asarray(qd), jnp.asarray(qdd))


@eqx.filter_jit
def _stack(reg, robot, q, qd, qdd):
    Y = jax.vmap(lambda a, b, c: reg(robot, a, b, c))(q, qd, qdd)
    return Y.reshape(-1, Y.shape[-1])


def random_samples(robot: Robot, n_samples: int, seed: int = 0, scale: float = np.pi):
    """Random (q, qd, qdd), each (n_samples, n), within the joint limits where they are finite."""
    rng = np.random.default_rng(seed)
    n = robot.nq
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    lo = np.where(np.isfinite(lo), lo, -scale)
    hi = np.where(np.isfinite(hi), hi, scale)
    q = rng.uniform(lo, hi, size=(n_samples, n))
    qd = rng.uniform(-scale, scale, size=(n_samples, n))
    qdd = rng.uniform(-scale, scale, size=(n_samples, n))
    return q, qd, qdd
