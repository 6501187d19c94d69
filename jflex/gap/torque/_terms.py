"""The kinds of torque-side term the gap diagnosis tries (:class:`._torque.TorqueTerm`), one class
each, and the table that names them (:data:`KINDS`).

The laws (friction, rotor inertia, gravity compensator, payload) are :mod:`jflex.effects` effects:
a :class:`LawTerm`'s columns are the effect's own generalised force, differentiated in its
coefficients (:mod:`._effect_term`), and a fitted one enters a simulation as that effect. The
others act between the measurement and the rigid model and are first-order corrections along the
measured motion: a joint's compliance (the link lagging its motor by ``tau_j / k``, the
quasi-static deflection of :class:`jflex.effects.FlexibleJoints`), play in the gear, a sensor's
delay. A kind added here (or an :class:`jflex.gap.EffectCandidate`) needs no edit elsewhere in
the diagnosis.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._dynamics import _rnea
from ..._program_cache import persistent_jit
from ..._sweep import flagged_vmap
from ...identify._physical import pseudo_inertia, pseudo_inertia_to_params
from ...data._signal import motion_band, zero_phase_lowpass
from ...effects._linear import TORQUE_FRACTION, CandidateInfo, DataScale, on_register, registered_candidates
from .._effect_term import FAMILIES, FAMILY_META, family_columns, family_of
from ._set import (CUTOFF_FACTOR, TorqueSet, TorqueTerm, _id_batch, fit_terms, on_rows, predict, term_columns,
                      weighted_inertia_columns)

# [s] grid of sensor delays, of either sign: the torque lagging the angles (d > 0), or the encoders
# lagging the torque (d < 0: a position read by a slower bus, or stamped at the end of a cycle)
DELAYS = tuple(np.round(np.concatenate([np.arange(0.001, 0.0605, 0.001), -np.arange(0.001, 0.0605, 0.001)]), 4))
DELAY_PLAUSIBLE = 0.05  # [s] a sensor's delay is a few samples to tens of milliseconds


def first_order_zero_phase(x, t, tau):
    """First-order low-pass run forwards and backwards (no lag), time constant ``tau`` [s]."""
    import scipy.signal as ss

    a = np.exp(-np.mean(np.diff(t)) / tau)
    return ss.filtfilt([1 - a], [1, -a], np.asarray(x, float), padtype="constant", padlen=0) if len(x) > 6 else np.asarray(x)


def play(x, b):
    """Play (backlash) operator of half-width ``b``: the driven side stays put until the driving
    side has crossed the gap."""
    y = np.empty_like(x)
    y[0] = x[0]
    for i in range(1, len(x)):
        y[i] = min(max(y[i - 1], x[i] - b), x[i] + b)
    return y


BACKLASH_B = (0.003, 0.005, 0.0075, 0.01, 0.0125, 0.015, 0.0175, 0.02, 0.025, 0.03)  # [rad] grid of backlash half-widths


# --- plausible ranges: a fitted value no machine has is reported, not named ---------------------------
PLAY_PLAUSIBLE = 0.02  # [rad] half-width of a gear's play: a few mrad (worn spur gears reach ~1 degree)
DEFLECTION_PLAUSIBLE = 0.05  # [rad] a transmission's deflection under the largest measured torque


def out_of_range(name: str, value: float, lo: float, hi: float, unit: str = "", why: str = "") -> str | None:
    """The sentence a fitted value outside ``[lo, hi]`` is reported with (None inside)."""
    if lo <= value <= hi:
        return None
    u = f" {unit}" if unit else ""
    return f"{name} = {value:.4g}{u} lies outside the plausible range [{lo:.4g}, {hi:.4g}]{u}" + (f" ({why})" if why else "")


PSEUDO_INERTIA_TOL = 1e-6  # relative to its largest eigenvalue: rounding, not a body's inertia
NEAREST_ITERATIONS = 5000  # at most, of the nearest rigid body's projected gradient (a few hundred on a planar arm)


def payload_implausible(theta) -> str | None:
    """Why payload parameters ``[m, m cx, m cy, m cz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` (inertia about
    the last body's origin) are no rigid body's, else None: a body has a positive mass and a
    positive semi-definite pseudo-inertia ``[[tr(I)/2 1 - I, m c], [m c^T, m]]`` (its second moments
    of mass; Wensing, Kim and Slotine, "Linear matrix inequalities for physically consistent
    inertial parameter identification"), which also holds the triangle inequalities of the
    principal moments. A fit outside that set absorbs something else."""
    p = np.asarray(theta, float)
    m, h = float(p[0]), p[1:4]
    if not m > 0:
        return (f"a payload of mass {m:.4g} kg with first moment {np.round(h, 4).tolist()} kg m is no rigid body "
                "(a body carried has a positive mass)")
    lam = np.linalg.eigvalsh(pseudo_inertia(p))
    if lam[0] < -PSEUDO_INERTIA_TOL * max(abs(lam[-1]), 1e-300):
        return (f"a payload of {m:.4g} kg whose inertia [Ixx, Iyy, Izz] = {np.round(p[[4, 6, 9]], 5).tolist()} kg m^2 about "
                f"the tool body's origin and first moment {np.round(h, 4).tolist()} kg m no rigid body has (its pseudo-"
                f"inertia matrix has the negative eigenvalue {lam[0]:.3g})")
    return None


def _body_map() -> np.ndarray:
    """(10, 10): inertial parameters from a pseudo-inertia's Frobenius-normed entries (linear)."""
    return np.stack([pseudo_inertia_to_params(_mat(e), np) for e in np.eye(10)], axis=1)


_IU = np.triu_indices(4)
_W = np.where(_IU[0] == _IU[1], 1.0, np.sqrt(2.0))  # a symmetric matrix's entries, Frobenius-normed


def _vec(J):
    return J[_IU] * _W


def _mat(v):
    J = np.zeros((4, 4))
    J[_IU] = v / _W
    return J + np.triu(J, 1).T


def _psd(v):
    lam, U = np.linalg.eigh(_mat(v))
    return _vec((U * np.maximum(lam, 0.0)) @ U.T)


_BODY_MAP = _body_map()


def nearest_rigid_body(theta, S, *, iterations: int = NEAREST_ITERATIONS, rtol: float = 1e-13) -> np.ndarray:
    """The inertial parameters of a rigid body (positive semi-definite pseudo-inertia) nearest to
    ``theta`` in the metric ``S`` (10 x 10, positive semi-definite): ``min (p - theta)' S (p - theta)``
    over the bodies. The parameters are linear in the pseudo-inertia, so this is a convex problem
    over the cone of positive semi-definite 4 x 4 matrices, solved by accelerated projected
    gradient (FISTA, restarted when the cost rises; the projection cuts the negative eigenvalues).
    ``S`` is singular where the data see nothing (a planar motion sees no out-of-plane moment):
    any body is as near there, and a local search scaled by the seen directions stalled."""
    theta = np.asarray(theta, float)
    A = _BODY_MAP
    H = A.T @ S @ A
    g0 = A.T @ S @ theta
    L = 2.0 * max(float(np.linalg.eigvalsh(H)[-1]), 1e-300)

    def cost(v):
        r = A @ v - theta
        return float(r @ S @ r)

    x = _psd(_vec(pseudo_inertia(theta)))
    y, t, fx = x.copy(), 1.0, cost(x)
    for k in range(iterations):
        xn = _psd(y - 2.0 * (H @ y - g0) / L)
        tn = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * t * t))
        fn = cost(xn)
        y = xn + ((t - 1.0) / tn) * (xn - x)
        if fn > fx:  # momentum overshot: restart from the last point
            y, tn = xn.copy(), 1.0
        done = k > 10 and abs(fx - fn) <= rtol * max(fx, 1e-300)
        x, t, fx = xn, tn, fn
        if done or fx == 0.0:
            break
    return A @ x


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


def _law_ranges(name, j, sc):
    """Per coefficient of the built-in family ``name`` at joint ``j``: ``(low, high)`` given the data's scale."""
    lvl = TORQUE_FRACTION * sc.tau_rms[j]
    if name == "viscous_friction":
        return [(0.0, TORQUE_FRACTION * sc.tau_std[j] / max(sc.qd_std[j], 1e-12))]
    if name == "coulomb_friction":
        return [(0.0, lvl)]
    if name == "stribeck_friction":
        return [(0.0, lvl), (0.0, lvl)]
    if name == "rotor_inertia":
        return [(0.0, TORQUE_FRACTION * sc.tau_std[j] / max(sc.qdd_std[j], 1e-12))]
    if name == "gravity_compensator":
        return [(-lvl, lvl)] * 4
    return None


# --- laws of jflex.effects ---------------------------------------------------------------------------
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
        if self.effect != "payload" or payload_implausible(theta) is None:
            return None
        return nearest_rigid_body(theta, metric())

    def implausible(self, theta, sets):
        if not sets:
            return None
        if self.effect == "payload":
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


# --- a joint's compliance, seen in torque data -----------------------------------------------------
def _jvp_row(robot, q, qd, qdd, dq, dqd, dqdd):
    # one direction per sample: forward mode through the traversal (the public rnea's analytic
    # derivative builds every direction's matrices, and compiles longer)
    f = lambda a, b, c: _rnea(robot, a, b, c, None, "rnea")
    return jax.jvp(f, (q, qd, qdd), (dq, dqd, dqdd))[1]


_jvp_batch = flagged_vmap(_jvp_row, in_axes=(None, 0, 0, 0, 0, 0, 0))  # checks as flags: see _torque._id_batch


def link_lag_column(s: TorqueSet, j: int, lag) -> np.ndarray:
    """(N, n) change of the rigid torques when the link of joint ``j`` lags the measured angle by
    ``lag`` (N,) per unit of it, to first order: minus RNEA's directional derivative along
    ``e_j (lag, d lag/dt, d2 lag/dt2)``."""
    lagd = np.gradient(lag, s.t)
    d = [np.zeros_like(s.q) for _ in range(3)]
    for k, v in enumerate((lag, lagd, np.gradient(lagd, s.t))):
        d[k][:, j] = v
    return -on_rows(_jvp_batch, (s.robot,), (s.q, s.qd, s.qdd, *d))


def smooth_torque(s: TorqueSet) -> np.ndarray:
    """The measured torque, low-passed (the set's own filter, else one at CUTOFF_FACTOR x the
    motion band): what a column built from the torque itself may differentiate."""
    if s.cutoff is not None:
        return s.tau
    if "smooth_tau" not in s.cache:
        h = float(np.mean(np.diff(s.t)))
        fc = min(CUTOFF_FACTOR * motion_band(s.q, h), 0.4 / h)
        s.cache["smooth_tau"] = zero_phase_lowpass(s.tau, h, fc)
    return s.cache["smooth_tau"]


def compliance_column(s: TorqueSet, j: int) -> np.ndarray:
    """(N, n) torque change per unit compliance ``1/k`` of a flexible joint ``j`` whose motor-side
    angle is what the encoder measured: the link lags it by the deflection ``tau_j / k`` (the
    measured joint torque, as the spring passes it on), so to first order in the compliance the
    rigid torques change by minus RNEA's directional derivative along ``e_j (tau_j, dtau_j/dt,
    d2tau_j/dt2)`` (the quasi-static deflection of :class:`jflex.effects.FlexibleJoints`; its own
    damping and the motor's inertia are left out: the latter is ``rotor_inertia``)."""
    key = ("compliance", j)
    if key not in s.cache:
        s.cache[key] = link_lag_column(s, j, smooth_torque(s)[:, j])
    return s.cache[key]


@dataclasses.dataclass(frozen=True)
class CompliantJoint(TorqueTerm):
    """A flexible joint in torque data: the link lagging its motor by ``tau_j / k`` (:func:`compliance_column`)."""

    joint: int
    hyper: None = None
    effect: ClassVar[str] = "joint_flexibility"
    signature: ClassVar[str] = "extra FRF peak / unmatched mode; in torques, the link lagging under load (tau_j / k)"

    def param_names(self):
        return ["compliance 1/k [rad/(N m)]"]

    def columns(self, s):
        return compliance_column(s, self.joint)[:, :, None]

    def implausible(self, theta, sets):
        return _compliance_implausible(float(theta[0]), self.joint, sets)


def _compliance_implausible(c, j, sets):
    tmax = max(float(np.abs(s.tau[:, j]).max()) for s in sets) if sets else 0.0
    return out_of_range("compliance 1/k", c, 0.0, DEFLECTION_PLAUSIBLE / max(tmax, 1e-12), "rad/(N m)",
                        f"a deflection of at most {DEFLECTION_PLAUSIBLE:g} rad under the largest measured torque")


# --- play in the gear ------------------------------------------------------------------------------
BACKLASH_ENGAGE = (0.004, 0.008, 0.012)  # [s] grid of engagement smoothing (contact compliance) time constants
BACKLASH_ENGAGE_FIRST = 0.008  # [s] the engagement time of the half-width grid search (and of a bare b)
BACKLASH_PULSES = (0.004, 0.008, 0.016, 0.032)  # [s] widths of the engagement-impulse basis
# a loaded gear with play: the link sits against the tooth face the transmitted torque pushes it
# to and crosses the play when that torque changes sign; the sign is smoothed over this fraction
# of the joint torque's standard deviation (the crossing's duration, unknown: a grid)
BACKLASH_SIGN_WIDTHS = (0.005, 0.01, 0.02, 0.05)
LOADED = "loaded"  # hyper-parameter tag of that variant: (LOADED, sign width)


def is_loaded(h) -> bool:
    """Whether a backlash hyper-parameter is the loaded-gear variant (see :func:`loaded_backlash_torque`)."""
    return isinstance(h, tuple) and len(h) == 2 and h[0] == LOADED


def backlash_hyper(h):
    """``(b, engagement time constant)`` from a term's hyper-parameter (a bare ``b`` takes 8 ms)."""
    return (float(h), BACKLASH_ENGAGE_FIRST) if np.ndim(h) == 0 else (float(h[0]), float(h[1]))


def backlash_torque(s: TorqueSet, j: int, h) -> np.ndarray:
    """Rigid torque change columns (N, n, 1 + len(BACKLASH_PULSES)) when the link of joint ``j``
    follows the measured (motor-side) angle through a play of half-width ``b``, ``h = (b, tau_e)``.

    Column 0: the link's posture and velocity (play output, engagement smoothed by a zero-phase
    first-order filter of time constant ``tau_e``) with the measured acceleration. Columns 1..:
    the engagement impulse, ``M(q_link)[:, j]`` times the link's extra acceleration, its velocity
    smoothed over each width of :data:`BACKLASH_PULSES`: the contact's stiffness and damping (how
    hard the teeth meet) set the impulse's shape, unknown, so it is a non-negative mixture."""
    b, tau_e = backlash_hyper(h)
    key = ("backlash", j, b, tau_e)
    if key not in s.cache:
        ql, qdl = s.q.copy(), s.qd.copy()
        ql[:, j] = first_order_zero_phase(play(s.q[:, j], b), s.t, tau_e)
        qdl[:, j] = np.gradient(ql[:, j], s.t)
        Fa = on_rows(_id_batch, (s.robot,), (ql, qdl, s.qdd))
        cols = [Fa - s.F0]
        for w in BACKLASH_PULSES:
            qdd = s.qdd.copy()
            qdd[:, j] = np.gradient(first_order_zero_phase(qdl[:, j], s.t, w), s.t)
            cols.append(on_rows(_id_batch, (s.robot,), (ql, qdl, qdd)) - Fa)
        s.cache[key] = np.stack(cols, axis=2)
    return s.cache[key]


def loaded_backlash_torque(s: TorqueSet, j: int, width: float) -> np.ndarray:
    """Columns (N, n, 2) of a loaded transmission with play at joint ``j``: the link lags the
    motor-side angle by ``tau_j / k + b sgn(tau_j)`` (the spring's deflection plus the half-play on
    the side the transmitted torque presses), ``theta = [1/k, b]``. To first order both are
    RNEA's directional derivative along ``e_j`` times the deflection and its rates, as in
    :func:`compliance_column`; ``sgn`` is ``tanh(tau_j / (width std(tau_j)))`` of the low-passed
    measured torque. The kinematic play of :func:`backlash_torque` suits a link that no load
    presses against a tooth face; a gravity- or inertia-loaded one crosses the play when its torque
    reverses, and its gear's compliance comes with it."""
    key = ("loaded_backlash", j, width)
    if key not in s.cache:
        tj = smooth_torque(s)[:, j]
        sg = np.tanh(tj / (width * max(float(np.std(tj)), 1e-300)))
        s.cache[key] = np.stack([compliance_column(s, j), link_lag_column(s, j, sg)], axis=2)
    return s.cache[key]



@dataclasses.dataclass(frozen=True)
class Play(TorqueTerm):
    """Backlash as kinematic play at ``joint`` (:func:`backlash_torque`), ``hyper = (b, engagement)``.
    Its candidate search also tries the loaded gear (:class:`LoadedPlay`) and keeps the better of
    the two by the information criterion (they free different numbers of coefficients)."""

    joint: int
    hyper: tuple | float = 0.01
    effect: ClassVar[str] = "backlash"
    signature: ClassVar[str] = "dead zone at reversals of motion or of the transmitted torque"

    def param_names(self):
        return ["engagement (1 = full play)"] + [f"impulse {w * 1e3:g} ms" for w in BACKLASH_PULSES]

    def columns(self, s):
        return backlash_torque(s, self.joint, self.hyper)

    def parameters(self, theta):
        out = super().parameters(theta)
        out["b [rad]"], out["engagement [s]"] = backlash_hyper(self.hyper)
        return out

    def implausible(self, theta, sets):
        return out_of_range("play half-width b", backlash_hyper(self.hyper)[0], 0.0, PLAY_PLAUSIBLE, "rad",
                            "a gear's play is a few mrad")

    def search(self, base_terms, base_delay, sets, inertia=None):
        rows = sum(s.tau.size for s in sets)
        bic = lambda f: rows * np.log(max(f.cost, 1e-300)) + f.terms[-1].n_params * np.log(rows)
        return min((fit_play_backlash(base_terms, base_delay, self.joint, sets, inertia),
                    fit_loaded_backlash(base_terms, base_delay, self.joint, sets, inertia)), key=bic)

    def probes(self):
        return (Play(self.joint, 0.01), LoadedPlay(self.joint, (LOADED, 0.01)))


@dataclasses.dataclass(frozen=True)
class LoadedPlay(Play):
    """Backlash in a loaded gear at ``joint`` (:func:`loaded_backlash_torque`), ``hyper = (LOADED, sign width)``."""

    def param_names(self):
        return ["compliance 1/k [rad/(N m)]", "b [rad]"]

    def columns(self, s):
        return loaded_backlash_torque(s, self.joint, self.hyper[1])

    def parameters(self, theta):
        out = TorqueTerm.parameters(self, theta)
        out["sign width [x std(tau)]"] = float(self.hyper[1])
        return out

    def implausible(self, theta, sets):
        return (out_of_range("play half-width b", float(theta[1]), 0.0, PLAY_PLAUSIBLE, "rad", "a gear's play is a few mrad")
                or _compliance_implausible(float(theta[0]), self.joint, sets))


def backlash(joint, hyper=None) -> Play:
    """A backlash term: :class:`LoadedPlay` for a loaded-gear hyper-parameter, else :class:`Play`
    (a nominal one: half-width 0.01 rad)."""
    return LoadedPlay(joint, hyper) if is_loaded(hyper) else Play(joint, 0.01 if hyper is None else hyper)


def fit_play_backlash(base_terms, base_delay, j, sets, inertia=None):
    """Kinematic play at joint ``j`` (:func:`backlash_torque`): the half-width on a grid (engagement
    BACKLASH_ENGAGE_FIRST), the engagement time on its grid, then the half-width refined around the best."""
    fit = lambda h: fit_terms(tuple(base_terms) + (Play(j, h),), base_delay, sets, inertia)
    best = min((fit((b, BACKLASH_ENGAGE_FIRST)) for b in BACKLASH_B), key=lambda f: f.cost)
    b = best.terms[-1].hyper[0]
    best = min([best] + [fit((b, te)) for te in BACKLASH_ENGAGE if te != BACKLASH_ENGAGE_FIRST], key=lambda f: f.cost)
    te = best.terms[-1].hyper[1]
    for step in (0.00125, 0.000625):
        best = min([best] + [fit((b + d, te)) for d in (-step, step) if b + d > 0], key=lambda f: f.cost)
        b = best.terms[-1].hyper[0]
    return best


def fit_loaded_backlash(base_terms, base_delay, j, sets, inertia=None):
    """A loaded gear with play at joint ``j`` (:func:`loaded_backlash_torque`), its sign width on a grid."""
    fits = (fit_terms(tuple(base_terms) + (LoadedPlay(j, (LOADED, w)),), base_delay, sets, inertia)
            for w in BACKLASH_SIGN_WIDTHS)
    return min(fits, key=lambda f: f.cost)


# --- a sensor's delay -------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class SensorDelay(TorqueTerm):
    """The torque measurement lagging the motion by ``hyper`` [s] (negative: the angles lag the
    torque): no coefficient, the fit's ``delay`` (the shift operator of :func:`._torque.fit_terms`),
    searched on :data:`DELAYS`."""

    joint: None = None
    hyper: float | None = None
    effect: ClassVar[str] = "sensor_delay"
    per_joint: ClassVar[bool] = False
    signature: ClassVar[str] = "phase lag: correlation with d tau/dt"

    def param_names(self):
        return []

    def columns(self, s):
        return np.zeros(s.q.shape + (0,))

    @property
    def delay(self):
        return self.hyper

    def parameters(self, theta):
        return {"delay [s]": float(self.hyper)}

    def implausible(self, theta, sets):
        return out_of_range("delay", float(self.hyper), -DELAY_PLAUSIBLE, DELAY_PLAUSIBLE, "s",
                            "a sensor's delay is a few samples to tens of milliseconds")

    def search(self, base_terms, base_delay, sets, inertia=None):
        base = tuple(t for t in base_terms if not isinstance(t, SensorDelay))  # one delay, refitted from scratch
        best = min((fit_terms(base, d, sets, inertia) for d in DELAYS), key=lambda f: f.cost)
        return dataclasses.replace(best, terms=best.terms + (SensorDelay(None, best.delay),))

    def signature_columns(self, s, fit):
        return (np.gradient(predict(fit, s), s.t, axis=0))[:, :, None]


# --- a drive's gain ----------------------------------------------------------------------------------
GAIN_PLAUSIBLE = 0.3  # |gain - 1|: a data-sheet torque constant, a gear's efficiency, a gauge's calibration
# are off by per cents to tens of per cents; a torque several times off is a scale error of the data
# (:mod:`._torque_scale`), not a drive


@dataclasses.dataclass(frozen=True)
class DriveGain(TorqueTerm):
    """The torque read at ``joint`` is ``1 + gamma`` times what the joint transmits: a motor
    current converted with a data-sheet torque constant, a gear whose efficiency the ratio leaves
    out, a torque sensor's calibration (the joint drive gains of M. Gautier and S. Briot, "Global
    identification of joint drive gains and dynamic parameters of robots"). Column: the nominal
    model's rigid torque at the joint, coefficient ``gamma``. With the inertial parameters refitted
    only a gain relative to the other joints shows (every torque times one factor is a scaled
    robot); a known mass on the robot fixes the absolute one."""

    joint: int
    hyper: None = None
    effect: ClassVar[str] = "drive_gain"
    signature: ClassVar[str] = "the joint's torque larger or smaller by a constant factor"

    def param_names(self):
        return ["gain - 1"]

    def bounds(self):
        return [-np.inf], [np.inf]

    def columns(self, s):
        out = np.zeros(s.q.shape + (1,))
        out[:, self.joint, 0] = s.F0[:, self.joint]
        return out

    def signature_columns(self, s, fit):
        # the column is the model's own torque, most of which the inertial refit absorbs (a heavier
        # link raises it too): what a residual can show of a gain is the part no inertial change makes
        col = term_columns(self, s)
        if fit is None or fit.delta is None:
            return col
        ok = np.isfinite(s.scale)
        w = np.where(ok, 1.0 / np.where(ok, s.scale, 1.0), 0.0)
        Yw, _ = weighted_inertia_columns(s)
        x = (col[:, :, 0] * w[None, :]).ravel()
        perp = x - Yw @ np.linalg.lstsq(Yw, x, rcond=1e-10)[0]
        return (perp.reshape(col.shape[:2]) * np.where(ok, s.scale, 0.0)[None, :])[:, :, None]

    def implausible(self, theta, sets):
        return out_of_range("drive gain - 1", float(theta[0]), -GAIN_PLAUSIBLE, GAIN_PLAUSIBLE, "",
                            "a torque constant or a gear's efficiency is off by tens of per cents at most")


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


# the torque-side candidates by name, in the order the diagnosis tries them
KINDS = {name: _law(name) for name in FAMILIES[:5]}
KINDS["backlash"] = Kind(backlash, 1 + len(BACKLASH_PULSES), signature=Play.signature)
KINDS["payload"] = _law("payload")
KINDS["sensor_delay"] = Kind(lambda joint, hyper: SensorDelay(None, 0.0 if hyper is None else float(hyper)), 1,
                             per_joint=False, signature=SensorDelay.signature)
# counted as the joint's stiffness and damping, as on the frequency side (one candidate, one count)
KINDS["joint_flexibility"] = Kind(lambda joint, hyper: CompliantJoint(joint), 2, signature=CompliantJoint.signature)
KINDS["drive_gain"] = Kind(lambda joint, hyper: DriveGain(joint), 1, signature=DriveGain.signature)


def make_term(name: str, joint=None, hyper=None) -> TorqueTerm:
    """The torque term of candidate ``name`` at ``joint`` (hyper-parameter ``hyper``, else its default)."""
    return KINDS[name](joint, hyper)


# --- effects that offer themselves as candidates (jflex.effects.register_candidate) ------------------
def data_scale(sets) -> DataScale:
    """What plausible ranges are relative to (:class:`jflex.effects.DataScale`), over the torque sets."""
    cat = lambda name: np.concatenate([getattr(s, name) for s in sets])
    dt = min(float(np.median(np.diff(s.t))) for s in sets)
    sc = DataScale.of(np.array([0.0, dt]), cat("qd"), cat("qdd"), cat("tau"))
    return sc._replace(model_rms=np.sqrt(np.mean(cat("F0") ** 2, axis=0)))


@persistent_jit
def _effect_columns(effect, robot, q, qd, qdd):
    return jax.vmap(lambda a, b, c: effect.regressor(robot, a, b, c))(q, qd, qdd)


@dataclasses.dataclass(frozen=True)
class RegisteredTerm(TorqueTerm):
    """A candidate effect class of :mod:`jflex.effects` that registered itself
    (:func:`jflex.effects.register_candidate`), at the placement whose first joint is ``joint``;
    ``hyper`` its held nonlinear parameter (searched on the class's grid). Its columns are the
    effect's own regressor (the Jacobian of the torque its law adds)."""

    effect: str
    joint: int | None = None
    hyper: object = None

    @property
    def info(self) -> CandidateInfo:
        return registered_candidates()[self.effect].candidate

    @property
    def signature(self) -> str:
        return self.info.signature

    def group(self, n: int) -> tuple:
        """The joint indices of its placement on an ``n``-joint robot."""
        info = self.info
        if info.per_joint_law:
            return (self.joint,)
        hit = [g for g in info.placements(n) if g[0] == self.joint]
        if hit:
            return tuple(hit[0])
        # placed by the user (a nominal effect) where the class does not try it: the next joints
        return tuple(range(min(self.joint, n - info.size), min(self.joint, n - info.size) + info.size))

    def build(self, robot, joints=None):
        names = tuple(robot.joint_names)
        return self.info.build(tuple(names[j] for j in (self.group(len(names)) if joints is None else joints)), self.hyper)

    def param_names(self):
        proto = self.info.build(tuple(f"_{i}" for i in range(self.info.size)), self.hyper)
        owners = proto.parameter_owners(None)
        leaves = [a for a in proto.linear_leaves for _ in range(int(np.prod(np.shape(getattr(proto, a)))))]
        return [(o.split(":", 1)[1] + "." if ":" in o else "") + f"{a} [{u}]"
                for o, a, u in zip(owners, leaves, proto.parameter_units())]

    def bounds(self):
        lo = 0.0 if self.info.nonnegative else -np.inf
        return [lo] * self.n_params, [np.inf] * self.n_params

    def label(self, joint_names) -> str:
        if self.joint is None or self.info.per_joint_law:
            return super().label(joint_names)
        return f"{self.effect}@" + "+".join(joint_names[j] for j in self.group(len(joint_names)))

    def columns(self, s: TorqueSet) -> np.ndarray:
        robot, n = s.robot, s.q.shape[1]
        whole = self.info.per_joint_law  # one effect on every joint gives every placement's columns
        key = ("registered", self.effect, None if whole else self.group(n), self.hyper)
        if key not in s.cache:
            eff = self.build(robot, tuple(range(n)) if whole else None)
            Y = on_rows(_effect_columns, (eff, robot), (s.q, s.qd, s.qdd))
            s.cache[key] = (Y, np.asarray(eff.parameter_joints(robot)))
        Y, owner = s.cache[key]
        return Y[:, :, owner == self.joint] if whole else Y

    def parameters(self, theta) -> dict:
        out = super().parameters(theta)
        if self.info.hyper is not None:
            out[self.info.hyper[1]] = float(self.hyper)
        return out

    def search(self, base_terms, base_delay, sets, inertia=None):
        if self.info.hyper is None:
            return super().search(base_terms, base_delay, sets, inertia)
        fits = [fit_terms(tuple(base_terms) + (dataclasses.replace(self, hyper=v),), base_delay, sets, inertia)
                for v in self.info.hyper[0]]
        return min(fits, key=lambda f: f.cost)

    def probes(self):
        # the residual is correlated with the columns at every grid value (a coupling's sign and
        # ratio are what the signature must not presume)
        if self.info.hyper is None:
            return (self,)
        return tuple(dataclasses.replace(self, hyper=v) for v in self.info.hyper[0])

    def contribute(self, parts, theta) -> None:
        parts.extra.append(self.build(parts.robot).with_parameters(np.asarray(theta, float)))

    def implausible(self, theta, sets):
        if not sets:
            return None
        robot = sets[0].robot
        return self.build(robot).implausible(robot, theta, data_scale(sets))


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
