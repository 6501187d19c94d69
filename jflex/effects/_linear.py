"""Effects linear in their parameters, and the registry through which such an effect offers itself
as a candidate to the gap diagnosis.

Industrial identification models (Gautier and Khalil, "Direct calculation of minimum set of inertial
parameters of serial robots"; Khalil and Dombre, "Modeling, Identification and Control of Robots")
are sums of terms linear in their coefficients: friction levels, offsets, motor inertias. An effect
of that kind writes its law once, as the energies and forces of :class:`AbstractEffect`; its
regressor columns (``tau = Y(q, qd, qdd) theta``) are the Jacobian of the torque it adds in those
coefficients (:func:`effect_torque`), so identification and diagnosis read the same law the
simulation integrates.

An effect class becomes a candidate of :func:`jflex.gap.diagnose` by declaring a
:class:`CandidateInfo` and registering itself with :func:`register_candidate` (a decorator); the
diagnosis enumerates the registry, so a new law needs no change in :mod:`jflex.gap`. Every
candidate carries plausible ranges of its coefficients (:meth:`AbstractLinearEffect.plausible_ranges`):
a fit outside them is a number no machine has, reported as such rather than named as a finding.
"""

from __future__ import annotations

from typing import Callable, ClassVar, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._base import AbstractEffect, Slots


class DataScale(NamedTuple):
    """What the plausible ranges are relative to, per joint (n,): the measured torque's standard
    deviation ``tau_std`` and root mean square ``tau_rms`` [N m], the joint rate's and acceleration's
    standard deviations ``qd_std`` [rad/s], ``qdd_std`` [rad/s^2] and maxima ``qd_max``; ``dt`` the
    sample time [s]; ``model_rms`` (optional) the nominal model's torque root mean square [N m] on
    the same motion."""

    tau_std: np.ndarray
    tau_rms: np.ndarray
    qd_std: np.ndarray
    qdd_std: np.ndarray
    qd_max: np.ndarray
    dt: float
    model_rms: np.ndarray | None = None

    @staticmethod
    def of(t, qd, qdd, tau) -> "DataScale":
        """The scale of one record (arrays (N, n)), or of several stacked along time."""
        tau, qd, qdd = (np.asarray(a, float) for a in (tau, qd, qdd))
        return DataScale(tau.std(axis=0), np.sqrt(np.mean(tau**2, axis=0)), qd.std(axis=0), qdd.std(axis=0),
                         np.abs(qd).max(axis=0), float(np.median(np.diff(np.asarray(t, float)))))


# A coefficient is plausible when the torque it accounts for is at most this many times the measured
# torque's spread at the joint (std; the root mean square for a constant term): an effect that needs
# more torque than the joint ever showed cancels another term rather than describing the machine.
TORQUE_FRACTION = 2.0


class CandidateInfo(NamedTuple):
    """How the gap diagnosis tries an effect class.

    - ``name``: the candidate's name in rankings and reports.
    - ``build(joint_names, hyper)``: the effect on those joints with unit start values (its
      coefficients enter linearly, so their values do not change its columns).
    - ``placements(n)``: the joint groups (tuples of indices) of an ``n``-joint robot it is tried at;
      its first joint is where the report places it.
    - ``per_joint_law``: the law acts on each joint by itself, so one effect built on every joint
      gives the columns of every placement at once (one compiled program).
    - ``signature``: what its residual looks like, for the report.
    - ``hyper``: ``(grid, label, default)`` of a nonlinear parameter searched on a grid, else None.
    - ``nonnegative``: whether its coefficients are bounded below by zero (friction levels, inertias).
    - ``size``: joints per placement.
    - ``subsumed_by``: a law whose presence in the nominal model at the same joint leaves this one
      nothing of its own beyond another candidate (not tried there), else None.
    """

    name: str
    build: Callable
    placements: Callable
    per_joint_law: bool = True
    signature: str = ""
    hyper: tuple | None = None
    nonnegative: bool = True
    size: int = 1
    subsumed_by: str | None = None


_REGISTRY: dict = {}  # candidate name -> effect class
_LISTENERS: list = []  # called with each class registered (the diagnosis' table of candidates)


def register_candidate(cls):
    """Class decorator: offer ``cls`` (an :class:`AbstractLinearEffect` with a ``candidate``
    :class:`CandidateInfo`) to the gap diagnosis."""
    info = getattr(cls, "candidate", None)
    if not isinstance(info, CandidateInfo):
        raise TypeError(f"register_candidate: {cls.__name__}.candidate must be a jflex.effects.CandidateInfo")
    _REGISTRY[info.name] = cls
    for f in _LISTENERS:
        f(cls)
    return cls


def registered_candidates() -> dict:
    """``{candidate name: effect class}`` of every registered candidate effect."""
    return dict(_REGISTRY)


def on_register(f) -> None:
    """Call ``f(cls)`` for every candidate class registered so far and later."""
    _LISTENERS.append(f)
    for cls in list(_REGISTRY.values()):
        f(cls)


def _slots(n: int) -> Slots:
    return Slots(n, slice(n, n), slice(0, 0), n, 0)


def effect_torque(effect: AbstractEffect, robot, q, qd, qdd, t=0.0):
    """The joint torque (n,) an effect that adds no coordinates or states asks of the motors along
    ``(q, qd, qdd)``: Lagrange's ``d/dt dT/dqd - dT/dq + dV/dq`` of its energies minus its
    generalised force (robot modifications, such as a payload's, are not included)."""
    s = _slots(robot.nq)
    T = lambda x, v: effect.kinetic_energy(robot, s, x, v)
    dT = lambda x, v: jax.grad(T, argnums=1)(x, v)
    _, a = jax.jvp(lambda v: dT(q, v), (qd,), (qdd,))
    _, b = jax.jvp(lambda x: dT(x, qd), (q,), (qd,))
    dL = jax.grad(lambda x: effect.potential_energy(robot, s, x) - T(x, qd))(q)
    z = effect.initial_state(robot, s)
    return a + b + dL - effect.generalized_force(robot, s, t, q, qd, z)


class AbstractLinearEffect(AbstractEffect):
    """An effect on the robot's joints whose torque is linear in the leaves ``linear_leaves``
    (each (k,), in that order): ``tau = regressor(robot, q, qd, qdd) @ parameters()``.

    Subclasses write the law (energies, forces), name the leaves and their units, and give
    :meth:`plausible_ranges`; the regressor, the parameter names and the plausibility check are
    derived here."""

    linear_leaves: ClassVar[tuple[str, ...]] = ()
    units: ClassVar[tuple[str, ...]] = ()  # per leaf
    candidate: ClassVar[CandidateInfo | None] = None

    def parameters(self):
        """The coefficients (k,) in the regressor's column order."""
        return jnp.concatenate([jnp.ravel(getattr(self, a)) for a in self.linear_leaves])

    def with_parameters(self, theta):
        """The same effect with the coefficients ``theta`` (k,)."""
        import equinox as eqx

        theta = jnp.asarray(theta, float)
        out, k = self, 0
        for a in self.linear_leaves:
            v = getattr(self, a)
            m = int(np.prod(np.shape(v)))
            out = eqx.tree_at(lambda e, a=a: getattr(e, a), out, theta[k:k + m].reshape(np.shape(v)))
            k += m
        return out

    def parameter_owners(self, robot) -> tuple[str, ...]:
        """The joint (or motor) each coefficient belongs to, for its name; default: the effect's
        ``joints`` for every leaf."""
        return tuple(j for _ in self.linear_leaves for j in self.joints)

    def parameter_joints(self, robot) -> tuple[int, ...]:
        """The joint index each coefficient acts at first (its column's placement in the diagnosis)."""
        from ._base import joint_indices

        idx = joint_indices(robot, self.joints, type(self).__name__)
        return tuple(i for _ in self.linear_leaves for i in idx)

    def parameter_names(self, robot) -> tuple[str, ...]:
        """``owner.leaf`` per coefficient, e.g. ``joint3.offset``."""
        owners = self.parameter_owners(robot)
        leaves = [a for a in self.linear_leaves for _ in range(int(np.prod(np.shape(getattr(self, a)))))]
        return tuple(f"{o}.{a}" for o, a in zip(owners, leaves))

    def parameter_units(self) -> tuple[str, ...]:
        return tuple(u for a, u in zip(self.linear_leaves, self.units) for _ in range(int(np.prod(np.shape(getattr(self, a))))))

    def torque(self, robot, q, qd, qdd):
        """The joint torque (n,) this effect asks of the motors (:func:`effect_torque`)."""
        return effect_torque(self, robot, q, qd, qdd)

    def regressor(self, robot, q, qd, qdd):
        """Columns (n, k) with ``torque = regressor @ parameters()``: the torque's Jacobian in the
        coefficients (exact: the torque is linear in them)."""
        return jax.jacfwd(lambda p: effect_torque(self.with_parameters(p), robot, q, qd, qdd))(self.parameters())

    def plausible_ranges(self, robot, scale: DataScale) -> list[tuple[float, float]]:
        """``(low, high)`` per coefficient that a machine can have, given the data's ``scale``."""
        raise NotImplementedError

    def implausible(self, robot, values, scale: DataScale) -> str | None:
        """A sentence naming the first coefficient of ``values`` (k,) outside its plausible range,
        its value and the range; None when all are plausible."""
        names, units = self.parameter_names(robot), self.parameter_units()
        for nm, u, v, (lo, hi) in zip(names, units, np.asarray(values, float), self.plausible_ranges(robot, scale)):
            if not lo <= v <= hi:
                return f"{nm} = {v:.4g} {u} lies outside the plausible range [{lo:.4g}, {hi:.4g}] {u}"
        return None


def torque_bound(scale: DataScale, idx, fraction: float = TORQUE_FRACTION, rms: bool = False) -> np.ndarray:
    """``fraction`` x the measured torque's spread (std, or rms for a constant term) at joints ``idx``.
    A constant term is bounded by the larger of the measured and the modelled rms: a sensor that
    reports the effort net of the weight it carries (a lifting torso's) reads near zero while the
    model asks for the whole weight, and the offset between the two is that weight."""
    s = scale.tau_rms if rms else scale.tau_std
    if rms and scale.model_rms is not None:
        s = np.maximum(s, scale.model_rms)
    return fraction * np.asarray(s)[list(idx)]
