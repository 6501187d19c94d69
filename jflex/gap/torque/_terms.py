"""The kinds of torque-side term the gap diagnosis tries (:class:`._torque.TorqueTerm`), one class
each, and the table that names them (:data:`KINDS`).

The laws (friction, rotor inertia, gravity compensator, payload) are :mod:`jflex.effects` effects:
a :class:`LawTerm`'s columns are the effect's own generalised force, differentiated in its
coefficients (:mod:`._effect_term`), and a fitted one enters a simulation as that effect. The
others act between the measurement and the rigid model and are first-order corrections along the
measured motion, each in its own module, its law in :mod:`jflex.effects`: a joint's compliance
(:mod:`._compliance`), play in the gear (:mod:`._backlash`), a sensor's delay
(:mod:`._sensor_delay`), a drive's gain (:mod:`._drive_gain`). The table's names and order are
:mod:`jflex.effects._registry`'s. A kind added there (or an :class:`jflex.gap.EffectCandidate`)
needs no edit elsewhere in the diagnosis.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from ...effects._linear import TORQUE_FRACTION, on_register
from ...effects._registry import (BACKLASH, COULOMB_FRICTION, DRIVE_GAIN, GRAVITY_COMPENSATOR, JOINT_FLEXIBILITY, PAYLOAD,
                                  ROTOR_INERTIA, SENSOR_DELAY, STRIBECK_FRICTION, TERMS, VISCOUS_FRICTION)
from ...effects._measured_joint import play  # noqa: F401 (re-exported: judge's black-box terms read it here)
from .._effect_term import FAMILY_META, family_columns, family_of, torque_share_implausible
# the backlash and compliance names re-exported here are the tests' and the judge's
from ._backlash import (BACKLASH_B, BACKLASH_ENGAGE, BACKLASH_PULSES, BACKLASH_SIGN_WIDTHS, LOADED, LoadedPlay, Play,
                        backlash, backlash_hyper, fit_loaded_backlash, fit_play_backlash)
from ._compliance import CompliantJoint, compliance_column, link_lag_column, smooth_torque
from ._drive_gain import DriveGain
from ._payload import nearest_rigid_body, payload_implausible
from ._plausible import data_scale, out_of_range
from ._registered import RegisteredTerm
from ._sensor_delay import DELAYS, SensorDelay
from ._set import TorqueSet, TorqueTerm, fit_terms


# --- laws of jflex.effects ---------------------------------------------------------------------------
def _law_ranges(name, j, sc):
    """Per coefficient of the built-in family ``name`` at joint ``j``: ``(low, high)`` given the data's scale."""
    lvl = TORQUE_FRACTION * sc.tau_rms[j]
    if name == VISCOUS_FRICTION:
        return [(0.0, TORQUE_FRACTION * sc.tau_std[j] / max(sc.qd_std[j], 1e-12))]
    if name == COULOMB_FRICTION:
        return [(0.0, lvl)]
    if name == STRIBECK_FRICTION:
        return [(0.0, lvl), (0.0, lvl)]
    if name == ROTOR_INERTIA:
        return [(0.0, TORQUE_FRACTION * sc.tau_std[j] / max(sc.qdd_std[j], 1e-12))]
    if name == GRAVITY_COMPENSATOR:
        return [(-lvl, lvl)] * 4
    return None


@dataclasses.dataclass(frozen=True)
class LawTerm(TorqueTerm):
    """A built-in family of :mod:`jflex.effects` (:data:`._effect_term.FAMILIES`) at one joint
    (``None``: the payload); ``hyper`` its held nonlinear parameter (the Stribeck velocity)."""

    effect: str
    joint: int | None = None
    hyper: float | None = None

    @property
    def meta(self):
        return FAMILY_META[self.effect]

    @property
    def per_joint(self) -> bool:
        return self.meta.per_joint

    @property
    def signature(self) -> str:
        return self.meta.signature

    def param_names(self):
        return list(self.meta.param_names)

    def bounds(self):
        return list(self.meta.lower), [np.inf] * self.n_params

    def columns(self, s: TorqueSet) -> np.ndarray:
        key = ("family", self.effect, self.hyper)
        if key not in s.cache:
            s.cache[key] = family_columns(s.robot, self.effect, self.hyper, *(jnp.asarray(a) for a in (s.q, s.qd, s.qdd)))
        per = family_of(s.robot, self.effect).per(0 if self.joint is None else self.joint)
        return s.cache[key][:, :, per] @ self.meta.mix

    def parameters(self, theta) -> dict:
        out = super().parameters(theta)
        if self.meta.hyper is not None:
            out[self.meta.hyper[2]] = float(self.hyper)
        return out

    def consistent(self, theta, metric):
        """A payload's parameters moved to the nearest rigid body's in the fit's metric
        (``metric()``: the cost's matrix in them, :func:`._torque._consistent`), None when they are
        one already; other laws have no such set (their bounds hold them)."""
        if self.effect != PAYLOAD or payload_implausible(theta) is None:
            return None
        return nearest_rigid_body(theta, metric())

    def implausible(self, theta, sets):
        if not sets:
            return None
        if self.effect == PAYLOAD:
            why = payload_implausible(theta)
            if why:
                return why
        ranges = None if self.joint is None else _law_ranges(self.effect, self.joint, data_scale(sets))
        if ranges is None:
            return torque_share_implausible(self, theta, sets)
        for nm, v, (lo, hi) in zip(self.param_names(), np.asarray(theta, float), ranges):
            msg = out_of_range(nm, float(v), lo, hi, why=f"{TORQUE_FRACTION:g} x the measured torque's spread")
            if msg:
                return msg
        return None

    def search(self, base_terms, base_delay, sets, inertia=None):
        if self.meta.hyper is None:
            return super().search(base_terms, base_delay, sets, inertia)
        fits = [fit_terms(tuple(base_terms) + (dataclasses.replace(self, hyper=v),), base_delay, sets, inertia)
                for v in self.meta.hyper[1]]
        return min(fits, key=lambda f: f.cost)

    def probes(self):
        return (self if self.meta.hyper is None else dataclasses.replace(self, hyper=self.meta.hyper[1][1]),)

    def contribute(self, parts, theta) -> None:
        parts.add(self.effect, self.joint, theta, self.hyper)


# --- the table ---------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Kind:
    """A torque-side candidate: ``make(joint, hyper)`` builds its term (``hyper`` None: the
    default); ``n_params`` (the parameters it adds, searched hyper-parameters included: the
    information criterion's penalty), ``per_joint`` (else one for the whole robot), ``subsumed_by``
    (a nominal kind at the same joint that already holds it) and ``signature`` (what its residual
    looks like)."""

    make: object
    n_params: int
    per_joint: bool = True
    subsumed_by: str | None = None
    signature: str = ""
    placements: object = None  # callable(n) -> the joints it is tried at (None: every joint)

    def __call__(self, joint=None, hyper=None) -> TorqueTerm:
        return self.make(joint, hyper)

    def joints(self, n: int):
        """The joints (indices) of an ``n``-joint robot it is tried at."""
        return range(n) if self.placements is None else list(self.placements(n))


def _law(name) -> Kind:
    meta = FAMILY_META[name]

    def make(joint, hyper):
        if hyper is None and meta.hyper is not None:
            hyper = meta.hyper[1][len(meta.hyper[1]) // 2]  # the nominal one: the middle of the grid
        return LawTerm(name, joint, hyper)

    return Kind(make, len(meta.param_names) + int(meta.hyper is not None), meta.per_joint, meta.subsumed_by, meta.signature)


# the kinds that are no family of jflex.effects, by name
_TERMS = {
    BACKLASH: Kind(backlash, 1 + len(BACKLASH_PULSES), signature=Play.signature),
    SENSOR_DELAY: Kind(lambda joint, hyper: SensorDelay(None, 0.0 if hyper is None else float(hyper)), 1,
                       per_joint=False, signature=SensorDelay.signature),
    # counted as the joint's stiffness and damping, as on the frequency side (one candidate, one count)
    JOINT_FLEXIBILITY: Kind(lambda joint, hyper: CompliantJoint(joint), 2, signature=CompliantJoint.signature),
    DRIVE_GAIN: Kind(lambda joint, hyper: DriveGain(joint), 1, signature=DriveGain.signature),
}
# the torque-side candidates by name, in the order the diagnosis tries them (the registry's)
KINDS = {name: _law(name) if name in FAMILY_META else _TERMS[name] for name in TERMS}


def make_term(name: str, joint=None, hyper=None) -> TorqueTerm:
    """The torque term of candidate ``name`` at ``joint`` (hyper-parameter ``hyper``, else its default)."""
    return KINDS[name](joint, hyper)


# --- effects that offer themselves as candidates (jflex.effects.register_candidate) ------------------
def _registered(cls) -> None:
    info = cls.candidate

    def make(joint, hyper):
        return RegisteredTerm(info.name, joint, info.hyper[2] if hyper is None and info.hyper is not None else hyper)

    proto = RegisteredTerm(info.name, 0, None if info.hyper is None else info.hyper[2])
    KINDS[info.name] = Kind(make, proto.n_params + int(info.hyper is not None), subsumed_by=info.subsumed_by,
                            signature=info.signature, placements=lambda n: [g[0] for g in info.placements(n)])


on_register(_registered)


def implausible(problem, cand, state) -> str | None:
    """Why the fitted parameters of candidate ``cand`` (:class:`._problem.Candidate`) in ``state``
    are ones no machine has (:meth:`._torque.TorqueTerm.implausible` on the training torque sets),
    else None: the diagnosis reports such a fit and does not name it."""
    tfit = getattr(state, "tfit", None)
    if tfit is None:
        return None
    k = 0
    for t in tfit.terms:
        if t.effect == cand.effect and t.joint == cand.joint:
            return t.implausible(np.asarray(tfit.theta[k:k + t.n_params]), problem.ttrain)
        k += t.n_params
    return None
