"""Play in a gear seen in torque data: the link following the measured (motor-side) angle through
the play of :func:`jflex.effects.play`, or, in a loaded gear, sitting on the tooth face its torque
presses (:func:`jflex.effects.loaded_play_side`)."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from ...effects._measured_joint import first_order_zero_phase, loaded_play_side, play
from ...effects._registry import BACKLASH
from ._compliance import _compliance_implausible, compliance_column, link_lag_column, smooth_torque
from ._plausible import out_of_range
from ._set import TorqueSet, TorqueTerm, _id_batch, fit_terms, on_rows

BACKLASH_B = (0.003, 0.005, 0.0075, 0.01, 0.0125, 0.015, 0.0175, 0.02, 0.025, 0.03)  # [rad] grid of backlash half-widths
PLAY_PLAUSIBLE = 0.02  # [rad] half-width of a gear's play: a few mrad (worn spur gears reach ~1 degree)


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
    key = (BACKLASH, j, b, tau_e)
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
        sg = loaded_play_side(tj, width)
        s.cache[key] = np.stack([compliance_column(s, j), link_lag_column(s, j, sg)], axis=2)
    return s.cache[key]



@dataclasses.dataclass(frozen=True)
class Play(TorqueTerm):
    """Backlash as kinematic play at ``joint`` (:func:`backlash_torque`), ``hyper = (b, engagement)``.
    Its candidate search also tries the loaded gear (:class:`LoadedPlay`) and keeps the better of
    the two by the information criterion (they free different numbers of coefficients)."""

    joint: int
    hyper: tuple | float = 0.01
    effect: ClassVar[str] = BACKLASH
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
