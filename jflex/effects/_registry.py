"""Every effect the library names, named once.

An effect's name is what a case file, a ranking and a report call it; here each name is a module
constant, and every table that needs it (the gap diagnosis' torque-side kinds and built-in
families, its frequency-side sites, the nested and confounded pairs of its selection, the names a
case may use) is derived from :data:`EFFECTS` or refers to the constant. The order of
:data:`EFFECTS` is the order the diagnosis tries the candidates in; it must not change (the
forward selection's ties are broken by it).
"""

from __future__ import annotations

import dataclasses

import numpy as np

VISCOUS_FRICTION = "viscous_friction"
COULOMB_FRICTION = "coulomb_friction"
STRIBECK_FRICTION = "stribeck_friction"
ROTOR_INERTIA = "rotor_inertia"
GRAVITY_COMPENSATOR = "gravity_compensator"
BACKLASH = "backlash"
PAYLOAD = "payload"
SENSOR_DELAY = "sensor_delay"
JOINT_FLEXIBILITY = "joint_flexibility"
DRIVE_GAIN = "drive_gain"
ASYMMETRIC_COULOMB = "asymmetric_coulomb"
TORQUE_OFFSET = "torque_offset"
COUPLED_DRIVE = "coupled_drive"
ORTHOGONAL_COMPLIANCE = "orthogonal_compliance"
LINK_FLEXIBILITY = "link_flexibility"
FRACTIONAL_DAMPING = "fractional_damping"
HYSTERETIC_DAMPING = "hysteretic_damping"

STRIBECK_VS = (0.03, 0.06, 0.12, 0.25, 0.5)  # [rad/s] grid of Stribeck velocities a candidate searches


@dataclasses.dataclass(frozen=True)
class FamilyMeta:
    """What the diagnosis needs to know of a built-in torque-side candidate, whatever the robot.

    A candidate's coefficients ``theta`` (``param_names``, bounded below by ``lower``) map to the
    family's free parameters at its joint as ``mix @ theta`` (the Stribeck level is fitted as
    ``Fs - Fc >= 0``). ``hyper``: ``(leaf, grid, label)`` of a nonlinear parameter held per fit and
    searched on ``grid`` (the Stribeck velocity), else None. ``subsumed_by``: a nominal family at
    the same joint that already holds this one. ``signature``: what its residual looks like."""

    param_names: tuple
    lower: tuple
    mix: np.ndarray
    per_joint: bool = True
    hyper: tuple | None = None
    subsumed_by: str | None = None
    signature: str = ""

    def spec_lower(self) -> np.ndarray:
        """Lower bound of each free parameter at a joint: 0 where made of coefficients bounded by 0."""
        return np.where(np.any((self.mix != 0) & np.isinf(np.asarray(self.lower))[None, :], axis=1), -np.inf, 0.0)


# How an effect is tried on torque data: FAMILY, a law of jflex.effects whose columns are read off
# its generalised force (:class:`FamilyMeta`); TERM, a correction along the measured motion that
# the diagnosis writes itself; REGISTERED, an effect class that registers itself
# (:func:`jflex.effects.register_candidate`); None, not on torque data.
FAMILY, TERM, REGISTERED = "family", "term", "registered"


@dataclasses.dataclass(frozen=True)
class Effect:
    """An effect's entry: its ``name``; ``torque``, how torque data try it (FAMILY, TERM,
    REGISTERED or None); ``family``, its :class:`FamilyMeta` when a built-in family; ``site``,
    where it sits in the frequency model (the kind of elastic site: ``"joint"``, ``"orth"``,
    ``"link"``; ``"tool"`` for a rigid body there; None: not a site); ``nested``, the simpler
    effect this one contains (a Stribeck law holds a Coulomb level)."""

    name: str
    torque: str | None = None
    family: FamilyMeta | None = None
    site: str | None = None
    nested: str | None = None


SITES = ("joint", "orth", "link", "tool")  # the order the frequency side tries its sites in

EFFECTS = {e.name: e for e in (
    Effect(VISCOUS_FRICTION, FAMILY, FamilyMeta(("Fv [N m s/rad]",), (0.0,), np.eye(1),
                                                signature="correlation with joint velocity")),
    Effect(COULOMB_FRICTION, FAMILY, FamilyMeta(("Fc [N m]",), (0.0,), np.eye(1), subsumed_by=STRIBECK_FRICTION,
                                                signature="correlation with sign of velocity")),
    Effect(STRIBECK_FRICTION, FAMILY,
           FamilyMeta(("Fc [N m]", "Fs-Fc [N m]"), (0.0, 0.0), np.array([[1.0, 0.0], [1.0, 1.0]]),
                      hyper=("stribeck_velocity", STRIBECK_VS, "vs [rad/s]"),
                      signature="sign of velocity, larger at low speed"), nested=COULOMB_FRICTION),
    Effect(ROTOR_INERTIA, FAMILY, FamilyMeta(("Ia [kg m^2]",), (0.0,), np.eye(1),
                                             signature="correlation with joint acceleration")),
    Effect(GRAVITY_COMPENSATOR, FAMILY,
           FamilyMeta(("B_cos1 [N m]", "B_sin1 [N m]", "B_cos2 [N m]", "B_sin2 [N m]"), (-np.inf,) * 4, np.eye(4),
                      signature="posture harmonics of the joint angle")),
    Effect(BACKLASH, TERM),
    Effect(PAYLOAD, FAMILY,
           FamilyMeta(("m [kg]", "m cx [kg m]", "m cy [kg m]", "m cz [kg m]", "Ixx [kg m^2]", "Ixy [kg m^2]",
                       "Iyy [kg m^2]", "Ixz [kg m^2]", "Iyz [kg m^2]", "Izz [kg m^2]"), (0.0,) + (-np.inf,) * 9,
                      np.eye(10), per_joint=False, signature="tool-mass regressor columns"), site="tool"),
    Effect(SENSOR_DELAY, TERM),
    Effect(JOINT_FLEXIBILITY, TERM, site="joint"),
    Effect(DRIVE_GAIN, TERM),
    Effect(ASYMMETRIC_COULOMB, REGISTERED),
    Effect(TORQUE_OFFSET, REGISTERED),
    Effect(COUPLED_DRIVE, REGISTERED),
    Effect(ORTHOGONAL_COMPLIANCE, site="orth"),
    Effect(LINK_FLEXIBILITY, site="link"),
    Effect(FRACTIONAL_DAMPING),
    Effect(HYSTERETIC_DAMPING),
)}

EFFECT_NAMES = tuple(EFFECTS)
FAMILY_META = {e.name: e.family for e in EFFECTS.values() if e.torque == FAMILY}
TERMS = tuple(e.name for e in EFFECTS.values() if e.torque in (FAMILY, TERM))  # the built-in torque kinds, in order
# the frequency side's elastic sites and tool body, in the order of SITES: ``{name: site}``
SITE_EFFECTS = {e.name: e.site for s in SITES for e in EFFECTS.values() if e.site == s}
NESTED = {e.name: e.nested for e in EFFECTS.values() if e.nested}  # complex -> the simpler effect it contains
# pairs a single data set cannot always tell apart: reported as ambiguous when close
CONFOUNDED = {frozenset(p) for p in [(SENSOR_DELAY, VISCOUS_FRICTION), (PAYLOAD, JOINT_FLEXIBILITY),
                                     (PAYLOAD, ROTOR_INERTIA), (COULOMB_FRICTION, HYSTERETIC_DAMPING),
                                     (COULOMB_FRICTION, BACKLASH), (COULOMB_FRICTION, STRIBECK_FRICTION),
                                     (ORTHOGONAL_COMPLIANCE, LINK_FLEXIBILITY),
                                     (FRACTIONAL_DAMPING, HYSTERETIC_DAMPING)]}
