"""A model is a rigid core plus effects; every analysis consumes this one object.

``x = [q, effect coordinates...]`` are the generalised coordinates, ``z`` the effects' internal
first-order states. The rigid robot contributes through CRBA and RNEA; each effect through its
energies (differentiated automatically) and its non-conservative force, see
:class:`jflex.effects.AbstractEffect`.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._checks import has_inertia
from ._dynamics import _crba, _rnea, forward_kinematics
from ._errors import ShapeError
from ._robot import PRISMATIC, Robot
from ._tree import support
from .effects._base import AbstractEffect, Slots


class Layout(NamedTuple):
    """Static bookkeeping of a model's vectors."""

    coord_names: tuple[str, ...]
    state_names: tuple[str, ...]
    slots: tuple[Slots, ...]

    @property
    def nx(self) -> int:
        return len(self.coord_names)

    @property
    def nz(self) -> int:
        return len(self.state_names)

    def indices(self, coords, where: str = "") -> tuple[int, ...]:
        """Indices in ``x`` of coordinates given by name or index; an unknown name is a
        :class:`ShapeError` that lists the model's coordinates (prefixed by ``where``)."""
        out = []
        for c in coords:
            if isinstance(c, str):
                if c not in self.coord_names:
                    raise ShapeError(f"{where}unknown coordinate '{c}'; coordinates: {list(self.coord_names)}")
                out.append(self.coord_names.index(c))
            else:
                out.append(int(c))
        return tuple(out)


class Model(eqx.Module):
    """Rigid robot + effects.

    **Arguments:** ``robot`` (:class:`jflex.Robot`), ``effects`` (sequence of
    :class:`jflex.effects.AbstractEffect`, applied in order).
    """

    robot: Robot
    effects: tuple[AbstractEffect, ...]

    def __init__(self, robot: Robot, effects=()):
        self.robot = robot
        self.effects = tuple(effects)

    @property
    def rigid(self) -> Robot:
        """The rigid robot after every effect's ``modify_robot`` (e.g. with a payload)."""
        r = self.robot
        for e in self.effects:
            r = e.modify_robot(r)
        return r

    @property
    def layout(self) -> Layout:
        r = self.rigid
        n = r.nq
        coords = list(r.joint_names)
        states: list[str] = []
        spans = []
        for e in self.effects:
            c, s = e.coord_names(r), e.state_names(r)
            spans.append((len(coords), len(coords) + len(c), len(states), len(states) + len(s)))
            coords += list(c)
            states += list(s)
        nx, nz = len(coords), len(states)
        slots = tuple(Slots(n, slice(a, b), slice(c, d), nx, nz) for a, b, c, d in spans)
        return Layout(tuple(coords), tuple(states), slots)

    @property
    def nx(self) -> int:
        return self.layout.nx

    @property
    def nz(self) -> int:
        return self.layout.nz

    def with_effects(self, *effects) -> "Model":
        """A new model with ``effects`` appended."""
        return Model(self.robot, self.effects + tuple(effects))


def _check(model: Model, x, name):
    if jnp.shape(x) != (model.nx,):
        raise ShapeError(
            f"{name} must have shape ({model.nx},) for this model (coordinates {list(model.layout.coord_names)}), "
            f"got {jnp.shape(x)}"
        )


def _effect_energy(model: Model, x, xd):
    r, lay = model.rigid, model.layout
    T = jnp.zeros(())
    V = jnp.zeros(())
    for e, s in zip(model.effects, lay.slots):
        T = T + e.kinetic_energy(r, s, x, xd)
        V = V + e.potential_energy(r, s, x)
    return T, V


def _pad(a, n, nx):
    return jnp.zeros(nx, a.dtype).at[:n].set(a) if nx > n else a


def mass_matrix(model: Model, x):
    """Generalised mass matrix (nx, nx): rigid CRBA plus the Hessian of the effects' kinetic energy."""
    _check(model, x, "x")
    r, lay = model.rigid, model.layout
    n, nx = r.nq, lay.nx
    M = jnp.zeros((nx, nx), dtype=x.dtype).at[:n, :n].set(_crba(r, x[:n], "mass_matrix"))
    T = lambda xd: _effect_energy(model, x, xd)[0]
    return M + jax.hessian(T)(jnp.zeros_like(x))


def bias_forces(model: Model, t, x, xd, z):
    """``h(x, xd) - sum f_e``: everything but ``M xdd`` and the input, shape (nx,)."""
    r, lay = model.rigid, model.layout
    n, nx = r.nq, lay.nx
    h = _pad(_rnea(r, x[:n], xd[:n], jnp.zeros_like(xd[:n]), None, "bias_forces"), n, nx)

    # Lagrange's terms of the effects' energies: d/dt(dT/dxd) - dT/dx + dV/dx at xdd = 0.
    def dT_dxd(x_):
        return jax.grad(lambda v: _effect_energy(model, x_, v)[0])(xd)

    _, dtdt = jax.jvp(dT_dxd, (x,), (xd,))
    dL = jax.grad(lambda x_: _effect_energy(model, x_, xd)[1] - _effect_energy(model, x_, xd)[0])(x)
    h = h + dtdt + dL
    for e, s in zip(model.effects, lay.slots):
        h = h - e.generalized_force(r, s, t, x, xd, z)
    return h


def input_matrix(model: Model):
    """Input matrix B (nx, n): by default each joint's actuator drives its joint coordinate."""
    r, lay = model.rigid, model.layout
    B = jnp.zeros((lay.nx, r.nq)).at[jnp.arange(r.nq), jnp.arange(r.nq)].set(1.0)
    for e, s in zip(model.effects, lay.slots):
        B = e.actuation(r, s, B)
    return B


def state_rate(model: Model, t, x, xd, z):
    """Time derivative of the internal states, shape (nz,)."""
    r, lay = model.rigid, model.layout
    parts = [e.state_rate(r, s, t, x, xd, z) for e, s in zip(model.effects, lay.slots)]
    return jnp.concatenate(parts) if parts else jnp.zeros(0)


def initial_state(model: Model):
    """Initial internal states z0 (nz,)."""
    r, lay = model.rigid, model.layout
    parts = [e.initial_state(r, s) for e, s in zip(model.effects, lay.slots)]
    return jnp.concatenate(parts) if parts else jnp.zeros(0)


def model_forward_dynamics(model: Model, t, x, xd, z, u):
    """``(xdd, zd)`` of the model under actuator input ``u`` (n,)."""
    _check(model, x, "x")
    _check(model, xd, "xd")
    M = mass_matrix(model, x)
    rhs = input_matrix(model) @ u - bias_forces(model, t, x, xd, z)
    L = jnp.linalg.cholesky(M)
    xdd = jax.scipy.linalg.cho_solve((L, True), rhs)
    return xdd, state_rate(model, t, x, xd, z)


def model_inverse_dynamics(model: Model, t, x, xd, xdd, z):
    """Generalised forces ``M xdd + h - sum f_e`` (nx,) needed for the motion (x, xd, xdd)."""
    return mass_matrix(model, x) @ xdd + bias_forces(model, t, x, xd, z)


class Linearization(NamedTuple):
    """``M xdd + C xd + K x = B u`` about a posture, over the coordinates ``names``."""

    M: jnp.ndarray
    C: jnp.ndarray
    K: jnp.ndarray
    B: jnp.ndarray
    names: tuple[str, ...]
    keep: tuple[int, ...]


def _static_forces(model: Model, t, x, xd, z):
    """Generalised forces that survive at rest: gravity, the effects' potential forces, minus
    their small-motion forces. At xd = 0 the velocity-quadratic Lagrange terms vanish together
    with their first derivatives, so this is all a linearisation about rest needs."""
    r, lay = model.rigid, model.layout
    n, nx = r.nq, lay.nx
    rest = jnp.zeros_like(x[:n])  # (not z: that name holds the effects' states below)
    g = _pad(_rnea(r, x[:n], rest, rest, None, "linearize"), n, nx)
    dV = jax.grad(lambda x_: _effect_energy(model, x_, jnp.zeros_like(x_))[1])(x)
    f = jnp.zeros(nx, dtype=x.dtype)
    for e, s in zip(model.effects, lay.slots):
        f = f + e.linear_force(r, s, t, x, xd, z)
    return g + dV - f


def linearize(model: Model, x0, *, hold: tuple[str, ...] | tuple[int, ...] = (), t=0.0) -> Linearization:
    """Linearise the model about the static posture ``x0`` (xd = 0).

    ``K = d(g + dV/dx - f)/dx`` (gravity stiffness included), ``C = -df/dxd``, ``M = M(x0)``,
    where ``f`` are the effects' small-motion forces (:meth:`AbstractEffect.linear_force`).
    ``hold`` names coordinates clamped to x0 (e.g. the motor angles under perfect position
    control): their rows and columns are removed, and only the kept ones are differentiated.
    """
    _check(model, x0, "x0")
    lay = model.layout
    x0 = jnp.asarray(x0)
    zero = jnp.zeros_like(x0)
    z0 = initial_state(model)
    held = set(lay.indices(hold, "linearize (hold): "))
    keep = tuple(i for i in range(lay.nx) if i not in held)
    idx = jnp.array(keep, dtype=int)
    embed = lambda base, sub: base.at[idx].set(sub)
    M = mass_matrix(model, x0)[jnp.ix_(idx, idx)]
    K = jax.jacfwd(lambda xs: _static_forces(model, t, embed(x0, xs), zero, z0)[idx])(x0[idx])
    C = jax.jacfwd(lambda vs: _static_forces(model, t, x0, embed(zero, vs), z0)[idx])(zero[idx])
    B = input_matrix(model)
    return Linearization(M, C, K, B[idx], tuple(lay.coord_names[i] for i in keep), keep)


def dynamic_stiffness(model: Model, x0, omega, *, hold=()):
    """Complex dynamic stiffness ``K - omega^2 M + i omega C`` (+ frequency-dependent effect terms)
    at one angular frequency ``omega`` [rad/s], over the kept coordinates."""
    lin = linearize(model, x0, hold=hold)
    D = lin.K - omega**2 * lin.M + 1j * omega * lin.C
    r, lay = model.rigid, model.layout
    idx = jnp.array(lin.keep, dtype=int)
    for e, s in zip(model.effects, lay.slots):
        extra = e.dynamic_stiffness(r, s, jnp.asarray(x0), omega)
        if extra is not None:
            D = D + extra[jnp.ix_(idx, idx)]
    return D


def gravity_stiffness(robot: Robot, q):
    """``dG/dq`` (n, n) of the rigid robot: the Hessian of its gravity potential, in closed form.

    With ``s_j`` the world axis of joint ``j``, ``M_i`` and ``h_i`` the mass and first moment of
    body ``i``'s subtree and ``o_i`` its origin, ``G_i = -g . u_i`` where ``u_i = s_i x (h_i - M_i o_i)``
    (revolute) or ``s_i M_i`` (prismatic). A revolute joint ``j`` at or below ``i`` rotates ``u_i``
    rigidly, ``dG_i/dq_j = -g . (s_j x u_i)``; a prismatic one leaves it; the rest follows by the
    Hessian's symmetry. (Forward-mode differentiation of ``gravity`` gives the same, at ~20x the
    cost outside ``jit``, where the frequency-side diagnosis calls it once per posture and
    structure.)"""
    has_inertia("gravity_stiffness", robot)
    n = robot.nq
    T = forward_kinematics(robot, q)
    R, o = T[:, :3, :3], T[:, :3, 3]
    inert = jnp.asarray(robot.inertia)
    h = inert[:, :1] * o + jnp.einsum("kij,kj->ki", R, inert[:, 1:4])
    below = np.zeros((n, n))  # below[i, k]: body k in the subtree of i (i itself included)
    rev = np.array([t != PRISMATIC for t in robot.joint_types])
    for k in range(n):
        below[support(robot, k), k] = 1.0
    Ms, hs = below @ inert[:, 0], below @ h
    sw = jnp.einsum("kij,kj->ki", R, jnp.asarray(robot.axis))
    u = jnp.where(rev[:, None], jnp.cross(sw, hs - Ms[:, None] * o), sw * Ms[:, None])
    g = jnp.asarray(robot.gravity)
    L = -(u @ jnp.cross(g, sw).T) * (below.T * rev[None, :])  # (i, j): j revolute, i in its subtree
    return L + L.T - jnp.diag(jnp.diag(L))


