"""Periodic Fourier-series excitation trajectories (the thesis "Posture Dependent Dynamics in Robotic Machining" Eq. 3.8, Swevers et al.) optimised
for the condition number of the base regressor under joint, velocity, acceleration and
workspace limits (Eqs. 3.9-3.11)."""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._dynamics import frame_placement
from .._errors import ParameterError
from .._robot import Robot
from ._base_params import BaseParameters
from ._regressor import Regressor


class FourierTrajectory(eqx.Module):
    """``qd_i(t) = sum_h a_ih cos(h w t) + b_ih sin(h w t)`` and its integral/derivative (Eq. 3.8).

    **Fields:** ``a``, ``b`` (n, N_h) [rad/s]; ``q0`` (n,) [rad]; ``omega_f`` () [rad/s].
    Period ``2 pi / omega_f``; the trajectory starts and ends at rest only if designed so.
    """

    a: jnp.ndarray
    b: jnp.ndarray
    q0: jnp.ndarray
    omega_f: jnp.ndarray

    @property
    def period(self):
        return 2 * jnp.pi / self.omega_f

    def __call__(self, t):
        """``(q, qd, qdd)`` at time ``t`` [s], each (n,); vmap over t for a record."""
        h = jnp.arange(1, self.a.shape[1] + 1)
        wh = self.omega_f * h
        c, s = jnp.cos(wh * t), jnp.sin(wh * t)
        q = self.q0 + (self.a / wh * s - self.b / wh * c).sum(axis=1)
        qd = (self.a * c + self.b * s).sum(axis=1)
        qdd = (-self.a * wh * s + self.b * wh * c).sum(axis=1)
        return q, qd, qdd

    def sample(self, t):
        """Record at times ``t`` (N,): ``(q, qd, qdd)`` each (N, n)."""
        return jax.vmap(self)(jnp.asarray(t))


class ExcitationResult(NamedTuple):
    """``trajectory``; ``cond``: cond(A) of the base regressor on the design grid;
    ``max_violation``: largest constraint violation relative to its limit range (0 when
    feasible); ``history``: cond after each penalty round."""

    trajectory: FourierTrajectory
    cond: float
    max_violation: float
    history: list


def _violations(traj, t, lo, hi, vmax, amax, ws):
    q, qd, qdd = traj.sample(t)
    rng = jnp.maximum(hi - lo, 1e-9)
    v = [jax.nn.relu(q - hi) / rng, jax.nn.relu(lo - q) / rng, jax.nn.relu(jnp.abs(qd) - vmax) / vmax, jax.nn.relu(jnp.abs(qdd) - amax) / amax]
    if ws is not None:
        robot, frame, wlo, whi = ws
        p = jax.vmap(lambda qq: frame_placement(robot, qq, frame)[:3, 3])(q)
        wr = jnp.maximum(whi - wlo, 1e-9)
        v += [jax.nn.relu(p - whi) / wr, jax.nn.relu(wlo - p) / wr]
    return jnp.concatenate([x.ravel() for x in v])


def design_excitation(
    robot: Robot,
    base: BaseParameters,
    regressor: Regressor = Regressor(viscous=False, coulomb=False),
    *,
    n_harmonics: int = 5,
    omega_f: float = 2 * np.pi * 0.1,
    n_samples: int = 50,
    velocity_limit=None,
    acceleration_limit=None,
    workspace=None,
    seed: int = 0,
    solver=None,
    penalties=(1e2, 1e4, 1e6),
    max_steps: int = 300,
) -> ExcitationResult:
    """Optimise a Fourier excitation for ``min log cond(A)`` subject to the limits (Eq. 3.9).

    **Arguments:**

    - ``base``: the base parameters whose columns form A (so that A has full column rank).
    - ``n_harmonics`` N_h; ``omega_f`` [rad/s]; ``n_samples`` per period on the design grid.
    - Joint limits from ``robot.lower/upper``; ``velocity_limit``/``acceleration_limit`` (n,)
      [rad/s, rad/s^2] default to ``robot.velocity_limit`` / none.
    - ``workspace``: ``(frame, lower (3,), upper (3,))`` box [m] for a frame's position.
    - ``solver``: an optimistix minimiser (default BFGS). Constraints enter as quadratic
      penalties of increasing weight (``penalties``).

    **Returns:** :class:`ExcitationResult`.
    """
    n = robot.nq
    lo, hi = np.asarray(robot.lower, float), np.asarray(robot.upper, float)
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        lo = np.where(np.isfinite(lo), lo, -np.pi)
        hi = np.where(np.isfinite(hi), hi, np.pi)
    vmax = np.asarray(robot.velocity_limit if velocity_limit is None else velocity_limit, float)
    vmax = np.where(np.isfinite(vmax), vmax, 2.0)
    amax = np.full(n, np.inf) if acceleration_limit is None else np.asarray(acceleration_limit, float)
    amax = np.where(np.isfinite(amax), amax, 1e9)
    if (vmax <= 0).any() or (amax <= 0).any():
        raise ParameterError("design_excitation: velocity and acceleration limits must be positive")
    ws = None
    if workspace is not None:
        frame, wlo, whi = workspace
        ws = (robot, frame, jnp.asarray(wlo, float), jnp.asarray(whi, float))
    t = jnp.arange(n_samples) * (2 * np.pi / omega_f) / n_samples
    rng = np.random.default_rng(seed)
    amp = 0.3 * vmax[:, None] / n_harmonics
    y = (
        jnp.asarray(rng.normal(size=(n, n_harmonics)) * amp),
        jnp.asarray(rng.normal(size=(n, n_harmonics)) * amp),
        jnp.asarray(0.5 * (lo + hi)),
    )
    args = tuple(jnp.asarray(x) for x in (lo, hi, vmax, amax))
    w = jnp.asarray(omega_f, float)

    def traj_of(y):
        return FourierTrajectory(y[0], y[1], y[2], w)

    def log_cond(y):
        A = base.columns(regressor.stack(robot, *traj_of(y).sample(t)))
        s = jnp.linalg.svd(A, compute_uv=False)
        return jnp.log(s[0] / s[-1])

    def loss(y, mu):
        v = _violations(traj_of(y), t, *args, ws)
        return log_cond(y) + mu * jnp.sum(v**2)

    solver = solver if solver is not None else optx.BFGS(rtol=1e-6, atol=1e-6)
    history = []
    for mu in penalties:
        sol = optx.minimise(loss, solver, y, args=jnp.asarray(mu), max_steps=max_steps, throw=False)
        y = sol.value
        history.append(float(jnp.exp(log_cond(y))))
    traj = traj_of(y)
    viol = float(jnp.max(_violations(traj, t, *args, ws), initial=0.0))
    return ExcitationResult(traj, float(jnp.exp(log_cond(y))), viol, history)
