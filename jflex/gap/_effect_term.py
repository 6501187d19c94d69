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
from .._sweep import flagged_vmap
from .._model import Model, _effect_kinetic, _effect_potential, initial_state
from ..identify._fit import Free, ParameterSpec
from ..effects._linear import TORQUE_FRACTION
from ..effects._registry import (COULOMB_FRICTION, FAMILY_META, GRAVITY_COMPENSATOR, PAYLOAD, ROTOR_INERTIA,
                                STRIBECK_FRICTION, STRIBECK_VS, VISCOUS_FRICTION, FamilyMeta)
from .torque._set import TorqueTerm, on_rows, term_columns

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
    dT = lambda x_, v: jax.grad(lambda v_: _effect_kinetic(model, x_, v_))(v)
    _, a = jax.jvp(lambda v: dT(x, v), (xd,), (xdd,))
    _, b = jax.jvp(lambda x_: dT(x_, xd), (x,), (xd,))
    dL = jax.grad(lambda x_: _effect_potential(model, x_) - _effect_kinetic(model, x_, xd))(x)
    tau = tau + a + b + dL
    for e, s in zip(model.effects, model.layout.slots):
        tau = tau - e.generalized_force(r, s, t, x, xd, z)
    return tau


def _column_row(model, spec, p, a, b, c):
    def tau(pp):
        m = spec.apply(model, pp, physical=True)
        return effect_forces(m, 0.0, a, b, c, initial_state(m))

    return jax.jacfwd(tau)(p)


# checks as flags, not eqx.error_if (see _torque._id_batch): a program the compilation cache keeps
_columns = flagged_vmap(_column_row, in_axes=(None, None, None, 0, 0, 0))


@dataclasses.dataclass(frozen=True, eq=False)
class EffectTerm(TorqueTerm):
    """An :class:`EffectCandidate` as a torque term (:class:`._torque.TorqueTerm`); fitted, it
    enters a simulation as its own effect with the fitted values."""

    bound: BoundCandidate
    joint: int | None = None
    hyper: None = None

    @property
    def effect(self) -> str:
        return self.bound.cand.name

    def bounds(self):
        return list(self.bound.lower()), [np.inf] * self.n_params

    def param_names(self):
        return list(self.bound.labels())

    def columns(self, s) -> np.ndarray:
        key = ("effect", id(self.bound))
        if key not in s.cache:
            s.cache[key] = self.bound.columns(jnp.asarray(s.q), jnp.asarray(s.qd), jnp.asarray(s.qdd))
        return s.cache[key]

    def contribute(self, parts, theta) -> None:
        m = self.bound.spec.apply(self.bound.model, jnp.asarray(theta, float), physical=True)
        parts.extra += list(m.effects)

    def implausible(self, theta, sets):
        return torque_share_implausible(self, theta, sets)


def torque_share_implausible(term, theta, sets) -> str | None:
    """The generic range of a term's coefficients: the torque it accounts for at each joint (rms)
    at most ``TORQUE_FRACTION`` x the measured torque's rms there (an effect that needs more torque
    than the joint ever showed cancels another term rather than describing the machine)."""
    if not term.n_params or not sets:
        return None
    theta = np.asarray(theta, float)
    num = sum(np.sum((term_columns(term, s) @ theta) ** 2, axis=0) for s in sets)
    den = sum(np.sum(s.tau**2, axis=0) for s in sets)
    rows = sum(s.tau.shape[0] for s in sets)
    r, lim = np.sqrt(num / rows), TORQUE_FRACTION * np.sqrt(den / rows)
    j = int(np.argmax(r / np.maximum(lim, 1e-300)))
    if r[j] <= lim[j]:
        return None
    names = sets[0].robot.joint_names
    vals = ", ".join(f"{k} = {v:.4g}" for k, v in term.parameters(theta).items())
    return (f"its torque at {names[j]} ({r[j]:.4g} N m rms) exceeds {TORQUE_FRACTION:g} x the measured torque's rms there "
            f"({lim[j] / TORQUE_FRACTION:.4g} N m), with {vals}")


# --- the built-in torque-side laws, read off jflex.effects ------------------------------------------
COULOMB_LIMIT = 1e-6  # [rad/s] a Stribeck velocity this small leaves the Coulomb level alone
SMOOTHING = 5e-3  # [rad/s] width of the smooth sign of every Coulomb-like law (dry friction is sharp)


# the free leaves' accessors are module-level functions, one object each: they are part of the key of
# the compiled program, which is then shared by every robot of the same structure
def _leaf(attr, i=0):
    return _LEAVES.setdefault((attr, i), lambda m: getattr(m.effects[i], attr))


_LEAVES: dict = {}


FAMILIES = tuple(FAMILY_META)


@dataclasses.dataclass(frozen=True)
class Family:
    """A built-in family on one robot: the law on every joint (one evaluation gives every joint's
    columns), its free parameters ``spec`` and ``per(j)``, the spec entries of joint ``j``."""

    name: str
    model: Model
    spec: ParameterSpec
    per: object
    meta: FamilyMeta

    def with_hyper(self, value) -> Model:
        """The family's model with its hyper-parameter ``value`` (scalar or (n,)) on every joint."""
        if self.meta.hyper is None or value is None:
            return self.model
        n = len(self.model.robot.joint_names)
        v = jnp.broadcast_to(jnp.asarray(value, float), (n,))
        return eqx.tree_at(lambda m: getattr(m.effects[0], self.meta.hyper[0]), self.model, v)


def family(robot, name: str) -> Family:
    """The built-in candidate family ``name`` (one of :data:`FAMILIES`) as effects on ``robot``."""
    from .. import effects as E

    names = tuple(robot.joint_names)
    n = len(names)
    if name == VISCOUS_FRICTION:
        effs = [E.JointFriction(names, viscous=1.0, smoothing=SMOOTHING)]
        free = (Free("viscous", _leaf("viscous")),)
        per = lambda j: [j]
    elif name == COULOMB_FRICTION:
        # stribeck 0: the level is coulomb (1 - exp(-(qd/COULOMB_LIMIT)^2)), linear in it, no bump
        effs = [E.JointFriction(names, coulomb=1.0, stribeck=0.0, stribeck_velocity=COULOMB_LIMIT, smoothing=SMOOTHING)]
        free = (Free("coulomb", _leaf("coulomb")),)
        per = lambda j: [j]
    elif name == STRIBECK_FRICTION:
        effs = [E.JointFriction(names, coulomb=1.0, stribeck=1.0, stribeck_velocity=STRIBECK_VS[2], smoothing=SMOOTHING)]
        free = (Free("coulomb", _leaf("coulomb")), Free("stribeck", _leaf("stribeck")))
        per = lambda j: [j, n + j]
    elif name == ROTOR_INERTIA:
        effs = [E.RotorInertia(names, 1.0)]
        free = (Free("inertia", _leaf("inertia")),)
        per = lambda j: [j]
    elif name == GRAVITY_COMPENSATOR:
        effs = [E.FourierGravityCompensator([1.0, 1.0], joint=j, sine=[1.0, 1.0]) for j in range(n)]
        free = tuple(f for j in range(n) for f in (Free(f"B{j}", _leaf("coefficients", j)), Free(f"A{j}", _leaf("sine", j))))
        # [cos q, sin q, cos 2q, sin 2q] of joint j: B_1, A_1, B_2, A_2
        per = lambda j: [4 * j, 4 * j + 2, 4 * j + 1, 4 * j + 3]
    elif name == PAYLOAD:
        effs = [E.Payload(np.ones(10))]
        free = (Free(PAYLOAD, _leaf("parameters")),)
        per = lambda j: list(range(10))
    else:
        raise KeyError(name)
    model = Model(robot, effs)
    return Family(name, model, ParameterSpec(free).bind(model), per, FAMILY_META[name])


_FAMILIES: dict = {}  # (id(robot), name) -> (robot, Family): one compiled program per family


def family_of(robot, name) -> Family:
    """:func:`family`, built once per robot (its functions are part of the compiled program's key)."""
    key = (id(robot), name)
    hit = _FAMILIES.get(key)
    if hit is None or hit[0] is not robot:
        if len(_FAMILIES) > 64:
            _FAMILIES.clear()
        hit = _FAMILIES[key] = (robot, family(robot, name))
    return hit[1]


def family_columns(robot, name, hyper, q, qd, qdd) -> np.ndarray:
    """(N, n, size) columns of a family along a motion, in its spec's order; the hyper-parameter
    (if the family has one) set to ``hyper``."""
    fam = family_of(robot, name)
    model = fam.with_hyper(hyper)
    p = fam.spec.physical(fam.spec.pack(model))
    return on_rows(_columns, (model, fam.spec, p), (q, qd, qdd))


class FamilyCoefficients:
    """Fitted coefficients gathered per family (spec vectors, zero where nothing was fitted) and
    the per-joint hyper-parameters, for a model of fixed structure (:meth:`effects`)."""

    def __init__(self, robot):
        self.robot = robot
        self.coeff = {name: np.zeros(family_of(robot, name).spec.size) for name in FAMILIES}
        self.hypers = {}
        self.extra = []  # effects of other (user) candidates, with their fitted values

    def add(self, name, joint, theta, hyper=None):
        fam = family_of(self.robot, name)
        self.coeff[name][fam.per(0 if joint is None else joint)] += fam.meta.mix @ np.asarray(theta, float)
        if fam.meta.hyper is not None and hyper is not None:
            h = self.hypers.setdefault(name, np.full(len(self.robot.joint_names), float(fam.meta.hyper[1][2])))
            h[joint] = float(hyper)

    def effects(self, families=FAMILIES) -> list:
        """Every family of ``families`` (default :data:`FAMILIES`) as effects with these values (one
        structure whatever was fitted: one compiled solve), then the extra effects. Coefficients
        bounded below by zero are clipped there (the bounded fit keeps them >= 0; a last-digit
        negative would be refused by the laws)."""
        out = []
        n = len(self.robot.joint_names)
        for name in families:
            fam = family_of(self.robot, name)
            lo = np.full(fam.spec.size, -np.inf)
            for j in range(n if fam.meta.per_joint else 1):
                lo[fam.per(j)] = fam.meta.spec_lower()
            p = np.maximum(self.coeff[name], lo)
            model = fam.with_hyper(self.hypers.get(name))
            out += list(fam.spec.apply(model, jnp.asarray(p), physical=True).effects)
        return out + list(self.extra)
