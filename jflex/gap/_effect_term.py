"""Candidate effects given as :mod:`jflex.effects` effects: the diagnosis reads their torque-side
columns off the effect's own equations of motion, so an effect class written once (in
``jflex.effects`` or in a user's file) becomes a candidate without a line in ``jflex.gap``.

Along a measured motion ``(q, qd, qdd)`` the torque a model with the effect needs is
``model_inverse_dynamics(Model(robot, [effect(p)]))``; less the rigid robot's, it is the effect's
contribution, and its Jacobian in the free parameters ``p`` (``jax.jacfwd``) gives the columns of
the linear least-squares refit. The free parameters must enter linearly (coefficients of a
friction law, an inertia, a compensator's harmonics); anything else in the effect (a Stribeck
velocity, a smoothing width) is held at the value the effect was built with. Effects that add
coordinates of their own (a flexible joint's motor angle) are not seen this way: their torque
depends on a motion that was not measured.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._dynamics import rnea
from .._errors import ParameterError
from .._model import Model, _effect_energy, initial_state
from ..identify._fit import Free, ParameterSpec

LINEARITY_RTOL = 1e-6  # columns at the start and at twice the start must agree this well


@dataclasses.dataclass(frozen=True, eq=False)
class EffectCandidate:
    """A candidate effect for :func:`jflex.gap.diagnose`.

    **Arguments:**

    - ``name``: the effect's name in the ranking and report (e.g. ``"cogging_torque"``).
    - ``effect``: a :class:`jflex.effects.AbstractEffect`, placed (its joints/links set) and built
      with start values; the values of non-free leaves are kept.
    - ``free``: the free parameters, as :class:`jflex.identify.Free` on the one-effect model
      ``Model(robot, [effect])`` (e.g. ``Free("Fc", lambda m: m.effects[0].coulomb)``); they must
      enter the effect's generalised force linearly.
    - ``joint``: the joint name the report places it at (``None``: not at one joint).
    - ``nonnegative``: free parameters that cannot be negative (a friction coefficient), by name.
    """

    name: str
    effect: object
    free: tuple
    joint: str | None = None
    nonnegative: tuple = ()

    def __post_init__(self):
        object.__setattr__(self, "free", tuple(self.free))
        if not self.free or not all(isinstance(f, Free) for f in self.free):
            raise ParameterError(f"EffectCandidate '{self.name}': free must be a non-empty sequence of jflex.identify.Free")
        unknown = set(self.nonnegative) - {f.name for f in self.free}
        if unknown:
            raise ParameterError(f"EffectCandidate '{self.name}': nonnegative names {sorted(unknown)} are not free parameters "
                                 f"({[f.name for f in self.free]})")

    def bind(self, robot) -> "BoundCandidate":
        """Check the candidate against ``robot`` and fix its parameter layout."""
        model = Model(robot, [self.effect])
        if model.nx != robot.nq or model.nz != 0:
            raise ParameterError(
                f"EffectCandidate '{self.name}': {type(self.effect).__name__} adds coordinates or states "
                f"({list(model.layout.coord_names[robot.nq:]) + list(model.layout.state_names)}); a torque-side candidate "
                "must act on the measured joints alone (a flexible joint needs a simulation)")
        spec = ParameterSpec(self.free).bind(model)
        return BoundCandidate(self, model, spec)


@dataclasses.dataclass(frozen=True, eq=False)
class BoundCandidate:
    cand: EffectCandidate
    model: Model
    spec: ParameterSpec

    @property
    def size(self) -> int:
        return self.spec.size

    def labels(self) -> tuple:
        return self.spec.labels()

    def lower(self) -> np.ndarray:
        lo = []
        for f, s in zip(self.spec.frees, self.spec.shapes):
            k = int(np.prod(s))
            lo += [0.0 if f.name in self.cand.nonnegative else -np.inf] * k
        return np.asarray(lo)

    def columns(self, q, qd, qdd) -> np.ndarray:
        """(N, n, size) columns along a motion; checked to be linear in the free parameters."""
        p0 = np.asarray(self.spec.physical(self.spec.pack(self.model)))
        p1 = np.where(p0 != 0, 2 * p0, 1.0)
        A0 = np.asarray(_columns(self.model, self.spec, jnp.asarray(p0), q, qd, qdd))
        A1 = np.asarray(_columns(self.model, self.spec, jnp.asarray(p1), q, qd, qdd))
        tol = LINEARITY_RTOL * max(float(np.abs(A0).max()), 1e-300)
        if float(np.abs(A1 - A0).max()) > tol:
            raise ParameterError(
                f"EffectCandidate '{self.cand.name}': its torque is not linear in the free parameters "
                f"{list(self.labels())}; hold the nonlinear ones fixed (they keep the effect's values) and free its coefficients")
        return A0


def effect_forces(model: Model, t, x, xd, xdd, z):
    """The effects' share of the generalised forces a motion needs: ``model_inverse_dynamics``
    less the robot's own RNEA, without the rigid mass matrix (only what the effects change: the
    robot they modify, the Lagrange terms of their energies, minus their forces)."""
    r = model.rigid
    tau = jnp.zeros_like(xd)
    if r is not model.robot:
        tau = rnea(r, x, xd, xdd) - rnea(model.robot, x, xd, xdd)
    dT = lambda x_, v: jax.grad(lambda v_: _effect_energy(model, x_, v_)[0])(v)
    _, a = jax.jvp(lambda v: dT(x, v), (xd,), (xdd,))
    _, b = jax.jvp(lambda x_: dT(x_, xd), (x,), (xd,))
    dL = jax.grad(lambda x_: _effect_energy(model, x_, xd)[1] - _effect_energy(model, x_, xd)[0])(x)
    tau = tau + a + b + dL
    for e, s in zip(model.effects, model.layout.slots):
        tau = tau - e.generalized_force(r, s, t, x, xd, z)
    return tau


@eqx.filter_jit
def _columns(model, spec, p, q, qd, qdd):
    def tau(pp, a, b, c):
        m = spec.apply(model, pp, physical=True)
        return effect_forces(m, 0.0, a, b, c, initial_state(m))

    return jax.vmap(lambda a, b, c: jax.jacfwd(tau)(p, a, b, c))(q, qd, qdd)


@dataclasses.dataclass(frozen=True, eq=False)
class EffectTerm:
    """An :class:`EffectCandidate` as a torque term of :mod:`._torque` (same interface as ``Term``)."""

    bound: BoundCandidate
    joint: int | None = None
    hyper: None = None

    @property
    def effect(self) -> str:
        return self.bound.cand.name

    @property
    def n_params(self) -> int:
        return self.bound.size

    def bounds(self):
        return list(self.bound.lower()), [np.inf] * self.n_params

    def param_names(self):
        return list(self.bound.labels())

    def columns(self, s) -> np.ndarray:
        key = ("effect", id(self.bound))
        if key not in s.cache:
            s.cache[key] = self.bound.columns(jnp.asarray(s.q), jnp.asarray(s.qd), jnp.asarray(s.qdd))
        return s.cache[key]

    def label(self, joint_names) -> str:
        return self.effect if self.joint is None else f"{self.effect}@{joint_names[self.joint]}"


# --- the built-in torque-side laws, read off jflex.effects ------------------------------------------
COULOMB_LIMIT = 1e-6  # [rad/s] a Stribeck velocity this small leaves the Coulomb level alone


# the free leaves' accessors are module-level functions, one object each: they are part of the key of
# the compiled program, which is then shared by every robot of the same structure
def _leaf(attr, i=0):
    return _LEAVES.setdefault((attr, i), lambda m: getattr(m.effects[i], attr))


_LEAVES: dict = {}


def family(robot, name: str, hyper=None, smoothing: float = 5e-3):
    """The built-in candidate family ``name`` as one effect (or one per joint) on every joint of
    ``robot`` and its free parameters: the columns of all joints come from one evaluation, and the
    candidate at joint j takes its own. ``hyper``: the Stribeck velocity [rad/s].
    **Returns** ``(model, spec, per_joint)`` with ``per_joint(j) -> column indices``."""
    from .. import effects as E

    names = tuple(robot.joint_names)
    n = len(names)
    if name == "viscous_friction":
        effs = [E.JointFriction(names, viscous=1.0, smoothing=smoothing)]
        free = (Free("viscous", _leaf("viscous")),)
        per = lambda j: [j]
    elif name == "coulomb_friction":
        effs = [E.JointFriction(names, coulomb=1.0, stribeck_velocity=COULOMB_LIMIT, smoothing=smoothing)]
        free = (Free("coulomb", _leaf("coulomb")),)
        per = lambda j: [j]
    elif name == "stribeck_friction":
        effs = [E.JointFriction(names, coulomb=1.0, stribeck=1.0, stribeck_velocity=float(hyper), smoothing=smoothing)]
        free = (Free("coulomb", _leaf("coulomb")), Free("stribeck", _leaf("stribeck")))
        per = lambda j: [j, n + j]
    elif name == "rotor_inertia":
        effs = [E.RotorInertia(names, 1.0)]
        free = (Free("inertia", _leaf("inertia")),)
        per = lambda j: [j]
    elif name == "gravity_compensator":
        effs = [E.FourierGravityCompensator([1.0, 1.0], joint=j, sine=[1.0, 1.0]) for j in range(n)]
        free = tuple(f for j in range(n) for f in (Free(f"B{j}", _leaf("coefficients", j)), Free(f"A{j}", _leaf("sine", j))))
        # [cos q, sin q, cos 2q, sin 2q] of joint j: B_1, A_1, B_2, A_2
        per = lambda j: [4 * j, 4 * j + 2, 4 * j + 1, 4 * j + 3]
    elif name == "payload":
        effs = [E.Payload(np.ones(10))]
        free = (Free("payload", _leaf("parameters")),)
        per = lambda j: list(range(10))
    else:
        raise KeyError(name)
    model = Model(robot, effs)
    return model, ParameterSpec(free).bind(model), per


_FAMILIES: dict = {}  # (id(robot), name) -> (robot, model, spec, per): one compiled program per family


def family_columns(robot, name, hyper, q, qd, qdd) -> tuple:
    """(N, n, size) columns of a family (:func:`family`) along a motion, and its ``per_joint``.
    The family's model and free-parameter spec are built once per robot (their functions are part
    of the compiled program's key); a Stribeck velocity is a leaf set into it."""
    key = (id(robot), name)
    hit = _FAMILIES.get(key)
    if hit is None or hit[0] is not robot:
        if len(_FAMILIES) > 64:
            _FAMILIES.clear()
        hit = _FAMILIES[key] = (robot, *family(robot, name, 0.1 if name == "stribeck_friction" else None))
    _, model, spec, per = hit
    if name == "stribeck_friction":
        model = eqx.tree_at(lambda m: m.effects[0].stribeck_velocity, model,
                            jnp.full(robot.nq, float(hyper)))
    p = spec.physical(spec.pack(model))
    return np.asarray(_columns(model, spec, p, q, qd, qdd)), per

