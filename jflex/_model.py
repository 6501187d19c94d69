"""A model is a rigid core plus effects; every analysis consumes this one object.

``x = [q, effect coordinates...]`` are the generalised coordinates, ``z`` the effects' internal
first-order states. The rigid robot contributes through CRBA and RNEA; each effect through its
energies (differentiated automatically) and its non-conservative force, see
:class:`jflex.effects.AbstractEffect`.
"""

from __future__ import annotations

import fnmatch
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._checks import has_inertia
from ._compiled import QUICK_COMPILE, compiled
from ._dynamics import _crba, _rnea, forward_kinematics
from ._errors import ParameterError, ShapeError
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
        if self.effects and any(k >= 0 for k in getattr(robot, "mimic", ())):
            # the effects index joints as coordinates; a follower joint has none of its own
            followers = [robot.joint_names[i] for i, k in enumerate(robot.mimic) if k >= 0]
            raise ParameterError(f"Model: effects on a robot with mimic joints ({followers} follow their leaders) "
                                 "are not supported; lock the followers (load_urdf(..., lock={...}) or joints=[...]) "
                                 "or load it with mimic='independent'")

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
        coords = list(getattr(r, "coordinate_names", r.joint_names))  # a mimic follower has no coordinate
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


def _effect_kinetic(model: Model, x, xd):
    r, lay = model.rigid, model.layout
    T = jnp.zeros(())
    for e, s in zip(model.effects, lay.slots):
        T = T + e.kinetic_energy(r, s, x, xd)
    return T


def _effect_potential(model: Model, x):
    r, lay = model.rigid, model.layout
    V = jnp.zeros(())
    for e, s in zip(model.effects, lay.slots):
        V = V + e.potential_energy(r, s, x)
    return V


def _pad(a, n, nx):
    return jnp.zeros(nx, a.dtype).at[:n].set(a) if nx > n else a


def mass_matrix(model: Model, x):
    """Generalised mass matrix (nx, nx): rigid CRBA plus the Hessian of the effects' kinetic energy."""
    _check(model, x, "x")
    r, lay = model.rigid, model.layout
    n, nx = r.nq, lay.nx
    M = jnp.zeros((nx, nx), dtype=x.dtype).at[:n, :n].set(_crba(r, x[:n], "mass_matrix"))
    T = lambda xd: _effect_kinetic(model, x, xd)
    return M + jax.hessian(T)(jnp.zeros_like(x))


def bias_forces(model: Model, t, x, xd, z):
    """``h(x, xd) - sum f_e``: everything but ``M xdd`` and the input, shape (nx,)."""
    r, lay = model.rigid, model.layout
    n, nx = r.nq, lay.nx
    h = _pad(_rnea(r, x[:n], xd[:n], jnp.zeros_like(xd[:n]), None, "bias_forces"), n, nx)

    # Lagrange's terms of the effects' energies: d/dt(dT/dxd) - dT/dx + dV/dx at xdd = 0.
    def dT_dxd(x_):
        return jax.grad(lambda v: _effect_kinetic(model, x_, v))(xd)

    _, dtdt = jax.jvp(dT_dxd, (x,), (xd,))
    # (each energy traced once: a derivative of T alone traces no V, and the other way round)
    dL = jax.grad(lambda x_: _effect_potential(model, x_) - _effect_kinetic(model, x_, xd))(x)
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


class Linearization(eqx.Module):
    """``M xdd + C xd + K x = B u`` about a posture, over the coordinates ``names``.

    ``M``, ``C``, ``K`` (nk, nk) and ``B`` (nk, n) are arrays; ``names`` (the kept coordinates)
    and ``keep`` (their indices in ``x``) are static, so a linearisation passes through
    ``jax.jit`` and ``jax.vmap``. It unpacks and indexes like the tuple
    ``(M, C, K, B, names, keep)``.
    """

    M: jnp.ndarray
    C: jnp.ndarray
    K: jnp.ndarray
    B: jnp.ndarray
    names: tuple[str, ...] = eqx.field(static=True)
    keep: tuple[int, ...] = eqx.field(static=True)

    def _astuple(self):
        return (self.M, self.C, self.K, self.B, self.names, self.keep)

    def __iter__(self):
        return iter(self._astuple())

    def __len__(self):
        return 6

    def __getitem__(self, i):
        return self._astuple()[i]


def resolve_hold(model: Model, hold) -> tuple[str, ...]:
    """Names of the held coordinates.

    ``hold`` is ``"actuated"`` (every coordinate an actuator drives: perfect position control,
    e.g. the motor side of flexible joints), a name or glob pattern (``"theta_*"``), an index,
    or a sequence of those; ``()`` or ``None`` holds nothing.
    """
    names = model.layout.coord_names
    if hold is None:
        return ()
    if isinstance(hold, (str, int, np.integer)):
        hold = (hold,)
    out: list[str] = []
    for h in hold:
        if isinstance(h, (bool, np.bool_)) or not isinstance(h, (str, int, np.integer)):
            raise ShapeError(f"hold: expected coordinate names, glob patterns, indices or 'actuated', got {h!r}")
        if isinstance(h, (int, np.integer)):
            if not 0 <= int(h) < len(names):
                raise ShapeError(f"hold: coordinate index {h} out of range; coordinates: {list(names)}")
            out.append(names[int(h)])
        elif h == "actuated":
            try:
                with jax.ensure_compile_time_eval():
                    B = np.asarray(input_matrix(model))
            except jax.errors.ConcretizationTypeError:
                raise ShapeError("hold='actuated' needs a structural input matrix; name the coordinates instead") from None
            out += [names[i] for i in np.flatnonzero(np.abs(B).sum(axis=1) > 0)]
        else:
            hits = [n for n in names if fnmatch.fnmatchcase(n, h)]
            if not hits:
                raise ShapeError(f"hold: '{h}' matches no coordinate; coordinates: {list(names)}")
            out += hits
    keep = [n for n in names if n not in out]
    if not keep:
        raise ShapeError(f"hold: holding {sorted(set(out))} leaves no free coordinate (coordinates {list(names)})")
    return tuple(dict.fromkeys(out))


def kept_coordinates(model: Model, hold) -> tuple[int, ...]:
    """Indices in ``x`` of the coordinates ``hold`` (see :func:`resolve_hold`) leaves free."""
    held = set(resolve_hold(model, hold))
    return tuple(i for i, c in enumerate(model.layout.coord_names) if c not in held)


def linearize(model: Model, x0, *, hold=(), t=0.0) -> Linearization:
    """Linearise the model about the static posture ``x0`` (xd = 0).

    ``K = d(g + dV/dx - f)/dx`` (gravity stiffness included), ``C = -df/dxd``, ``M = M(x0)``,
    where ``f`` are the effects' small-motion forces (:meth:`AbstractEffect.linear_force`).
    ``hold`` names coordinates clamped to x0 (e.g. the motor angles under perfect position
    control): ``"actuated"``, names, glob patterns such as ``"theta_*"`` or indices, as in
    :func:`jflex.modal_analysis` (see :func:`resolve_hold`); their rows and columns are removed,
    and only the kept ones are differentiated.

    Un-jitted, runs one compiled program per robot, model structure and ``hold`` (another
    posture or other parameters of the same robot and effects do not trace again); jit-, vmap-
    and grad-compatible.
    """
    _check(model, x0, "x0")
    return _linearize(model, jnp.asarray(x0), kept_coordinates(model, hold), t)


def _linear_forces(model: Model, t, x, xd, z):
    """Sum of the effects' small-motion forces :meth:`AbstractEffect.linear_force` (nx,)."""
    r, lay = model.rigid, model.layout
    f = jnp.zeros(lay.nx, dtype=jnp.result_type(x, xd))
    for e, s in zip(model.effects, lay.slots):
        f = f + e.linear_force(r, s, t, x, xd, z)
    return f


def _linearize_impl(model: Model, x0, keep: tuple[int, ...], t) -> Linearization:
    # The forces that survive at rest are gravity, the effects' potential forces and minus their
    # small-motion forces (at xd = 0 the velocity-quadratic Lagrange terms vanish together with
    # their first derivatives). Each term is differentiated on its own: gravity through its
    # closed-form Hessian, the rest by forward mode over the kept coordinates. Differentiating
    # their sum traced the rigid RNEA once for K and again (with zero tangents) for C: about three
    # times the program, and its compile time.
    r, lay = model.rigid, model.layout
    n = r.nq
    zero = jnp.zeros_like(x0)
    z0 = initial_state(model)
    idx = jnp.array(keep, dtype=int)
    sub = jnp.ix_(idx, idx)
    embed = lambda base, part: base.at[idx].set(part)
    M = mass_matrix(model, x0)[sub]
    Kg = jnp.zeros((lay.nx, lay.nx), dtype=x0.dtype).at[:n, :n].set(_gravity_stiffness(r, x0[:n]))[sub]
    f_of_x = lambda xs: jax.grad(lambda y: _effect_potential(model, embed(x0, y)))(xs) \
        - _linear_forces(model, t, embed(x0, xs), zero, z0)[idx]
    K = Kg + jax.jacfwd(f_of_x)(x0[idx])
    C = -jax.jacfwd(lambda vs: _linear_forces(model, t, x0, embed(zero, vs), z0)[idx])(zero[idx])
    B = input_matrix(model)
    return Linearization(M, C, K, B[idx], tuple(lay.coord_names[i] for i in keep), keep)


_linearize = compiled(_linearize_impl, compiler_options=QUICK_COMPILE)


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
    return _gravity_stiffness(robot, q)


def _gravity_stiffness(robot: Robot, q):
    if robot.mimic:  # coupled coordinates: the closed form walks joints, not coordinates
        rest = jnp.zeros_like(q)
        return jax.jacfwd(lambda q_: _rnea(robot, q_, rest, rest, None, "gravity_stiffness"))(q)
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


