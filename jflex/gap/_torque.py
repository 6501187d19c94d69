"""Torque-side terms of the gap diagnosis: each effect as columns of an equation-error model.

Along a measured motion the inverse dynamics of the nominal model plus effects is

$$ \\tau(t) = S_d\\big[\\tau_{rigid}(q, \\dot q, \\ddot q) + \\sum_e Y_e(q, \\dot q, \\ddot q; h_e)\\,\\theta_e\\big], $$

linear in every effect's coefficients ``theta_e`` once its few nonlinear hyper-parameters ``h_e``
(Stribeck velocity, sensor delay ``d`` of the shift operator ``S_d``) are fixed. So each refit is
a bounded linear least-squares solve (warm start: the hyper-parameters of effects already in the
model are kept; only a new effect's are searched on a grid). Each term's columns equal minus the
generalised force of the matching :mod:`jflex.effects` effect (checked in the tests).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import scipy.optimize as so

from .._dynamics import regressor, rnea

EPS_SIGN = 0.005  # [rad/s] width of the smooth sign used by every Coulomb-like term (dry friction is sharp)
STRIBECK_VS = (0.03, 0.06, 0.12, 0.25, 0.5)  # [rad/s] grid of Stribeck velocities
DELAYS = tuple(np.round(np.arange(0.001, 0.0605, 0.001), 4))  # [s] grid of sensor delays


@dataclasses.dataclass
class TorqueSet:
    """Precomputed quantities of one torque data set (numpy, (N, n) unless noted)."""

    name: str
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    F0: np.ndarray  # rigid inverse dynamics of the nominal robot
    scale: np.ndarray  # (n,) std of the measured torque per joint
    Ypay: np.ndarray  # (N, n, 4) regressor columns [m, mcx, mcy, mcz] of the last link
    dFdq: np.ndarray  # (N, n, n) d tau_rigid / d q
    q_extra: np.ndarray
    extra_joints: tuple
    robot: object = None
    cache: dict = dataclasses.field(default_factory=dict)  # backlash torques per (joint, b)


@jax.jit
def _id_batch(robot, q, qd, qdd):
    return jax.vmap(lambda a, b, c: rnea(robot, a, b, c))(q, qd, qdd)


def zero_phase_lowpass(x, t, tau):
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


@jax.jit
def _rigid_batch(robot, q, qd, qdd):
    f = lambda a, b, c: rnea(robot, a, b, c)
    F = jax.vmap(f)(q, qd, qdd)
    J = jax.vmap(jax.jacfwd(f, argnums=0))(q, qd, qdd)
    Y = jax.vmap(lambda a, b, c: regressor(robot, a, b, c))(q, qd, qdd)
    return F, J, Y


def torque_set(robot, ds) -> TorqueSet:
    """Precompute one torque data set (:class:`jflex.gap.Dataset`) for ``robot``."""
    a = ds.arrays
    q, qd, qdd = (jnp.asarray(a[k]) for k in ("q", "qd", "qdd"))
    F, J, Y = _rigid_batch(robot, q, qd, qdd)
    n = robot.nq
    Ypay = np.asarray(Y)[:, :, 10 * (n - 1): 10 * n]
    return TorqueSet(ds.name, a["t"], a["q"], a["qd"], a["qdd"], a["tau"], np.asarray(F),
                     np.maximum(a["tau"].std(axis=0), 1e-9), Ypay, np.asarray(J), a["q_extra"], ds.extra_joints, robot)


BACKLASH_ENGAGE = (0.004, 0.008, 0.012)  # [s] grid of engagement smoothing (contact compliance) time constants
BACKLASH_ENGAGE_FIRST = 0.008  # [s] the engagement time of the half-width grid search (and of a bare b)
BACKLASH_PULSES = (0.004, 0.008, 0.016, 0.032)  # [s] widths of the engagement-impulse basis


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
        ql[:, j] = zero_phase_lowpass(play(s.q[:, j], b), s.t, tau_e)
        qdl[:, j] = np.gradient(ql[:, j], s.t)
        Fa = np.asarray(_id_batch(s.robot, jnp.asarray(ql), jnp.asarray(qdl), jnp.asarray(s.qdd)))
        cols = [Fa - s.F0]
        for w in BACKLASH_PULSES:
            qdd = s.qdd.copy()
            qdd[:, j] = np.gradient(zero_phase_lowpass(qdl[:, j], s.t, w), s.t)
            cols.append(np.asarray(_id_batch(s.robot, jnp.asarray(ql), jnp.asarray(qdl), jnp.asarray(qdd))) - Fa)
        s.cache[key] = np.stack(cols, axis=2)
    return s.cache[key]


def held_sign(v, tol):
    """sign(v) held through stretches where |v| < tol (the side of the last motion)."""
    s = np.sign(v) * (np.abs(v) >= tol)
    out = np.empty_like(s)
    last = np.sign(v[0]) if v[0] != 0 else 1.0
    for i, x in enumerate(s):  # noqa: a short loop on (N,) once per data set
        if x != 0:
            last = x
        out[i] = last
    return out


def shift(X, t, d):
    """``S_d X``: the signal delayed by ``d`` [s] (linear interpolation; the first samples hold)."""
    if d == 0:
        return X
    flat = X.reshape(X.shape[0], -1)
    out = np.empty_like(flat)
    for k in range(flat.shape[1]):
        out[:, k] = np.interp(t - d, t, flat[:, k])
    return out.reshape(X.shape)


@dataclasses.dataclass(frozen=True)
class Term:
    """One effect on the torque side: ``effect`` at ``joint`` (index or None)."""

    effect: str
    joint: int | None
    hyper: float | tuple | None = None  # Stribeck velocity [rad/s], delay [s] or backlash (b [rad], engagement [s])

    @property
    def n_params(self) -> int:
        return {"stribeck_friction": 2, "gravity_compensator": 4, "payload": 10, "sensor_delay": 0,
                "backlash": 1 + len(BACKLASH_PULSES)}.get(self.effect, 1)

    def bounds(self):
        lo = {"gravity_compensator": [-np.inf] * 4, "payload": [0.0] + [-np.inf] * 9}.get(
            self.effect, [0.0] * self.n_params)
        return lo, [np.inf] * self.n_params

    def param_names(self):
        return {
            "viscous_friction": ["Fv [N m s/rad]"], "coulomb_friction": ["Fc [N m]"],
            "stribeck_friction": ["Fc [N m]", "Fs-Fc [N m]"], "rotor_inertia": ["Ia [kg m^2]"],
            "gravity_compensator": ["B_cos1 [N m]", "B_sin1 [N m]", "B_cos2 [N m]", "B_sin2 [N m]"],
            "payload": ["m [kg]", "m cx [kg m]", "m cy [kg m]", "m cz [kg m]", "Ixx [kg m^2]", "Ixy [kg m^2]",
                        "Iyy [kg m^2]", "Ixz [kg m^2]", "Iyz [kg m^2]", "Izz [kg m^2]"],
            "backlash": ["engagement (1 = full play)"] + [f"impulse {w * 1e3:g} ms" for w in BACKLASH_PULSES],
            "sensor_delay": [],
        }[self.effect]

    def columns(self, s: TorqueSet) -> np.ndarray:
        """(N, n, k) columns: tau += columns @ theta."""
        N, n = s.q.shape
        j = self.joint
        out = np.zeros((N, n, self.n_params))
        e = self.effect
        if e == "viscous_friction":
            out[:, j, 0] = s.qd[:, j]
        elif e == "coulomb_friction":
            out[:, j, 0] = np.tanh(s.qd[:, j] / EPS_SIGN)
        elif e == "stribeck_friction":
            sg = np.tanh(s.qd[:, j] / EPS_SIGN)
            out[:, j, 0] = sg
            out[:, j, 1] = np.exp(-((s.qd[:, j] / self.hyper) ** 2)) * sg
        elif e == "rotor_inertia":
            out[:, j, 0] = s.qdd[:, j]
        elif e == "gravity_compensator":
            qj = s.q[:, j]
            # the compensator's torque opposes the columns' sign convention: tau_motor = ... - tau_GC
            out[:, j, :] = -np.stack([np.cos(qj), np.sin(qj), np.cos(2 * qj), np.sin(2 * qj)], axis=1)
        elif e == "payload":
            out[:] = s.Ypay
        elif e == "backlash":
            # motor-side encoder; the link follows through the play (hyper = (half-width, engagement))
            out[:, :, :] = backlash_torque(s, j, self.hyper)
        return out

    def label(self, joint_names) -> str:
        return self.effect if self.joint is None else f"{self.effect}@{joint_names[self.joint]}"


@dataclasses.dataclass
class TorqueFit:
    terms: tuple
    delay: float
    theta: np.ndarray
    cost: float


def _design(terms, delay, s: TorqueSet):
    cols = [t.columns(s) for t in terms if t.n_params]
    A = np.concatenate(cols, axis=2) if cols else np.zeros(s.q.shape + (0,))
    A = shift(A, s.t, delay)
    y = s.tau - shift(s.F0, s.t, delay)
    w = 1.0 / s.scale
    return (A * w[None, :, None]).reshape(A.shape[0] * A.shape[1], A.shape[2]), (y * w[None, :]).ravel()


def fit_terms(terms, delay, sets) -> TorqueFit:
    """Bounded least squares of the terms' coefficients on the torque sets (channel-normalised)."""
    As, ys = zip(*[_design(terms, delay, s) for s in sets])
    A, y = np.concatenate(As), np.concatenate(ys)
    p = A.shape[1]
    if p == 0:
        return TorqueFit(tuple(terms), delay, np.zeros(0), float(y @ y))
    lo = np.concatenate([t.bounds()[0] for t in terms if t.n_params])
    hi = np.concatenate([t.bounds()[1] for t in terms if t.n_params])
    # column scaling keeps the bounded solver well conditioned (payload and friction differ by 1e3)
    cs = np.maximum(np.linalg.norm(A, axis=0), 1e-12)
    r = so.lsq_linear(A / cs, y, bounds=(lo * cs, hi * cs), method="bvls" if p <= 40 else "trf")
    theta = r.x / cs
    res = A @ theta - y
    return TorqueFit(tuple(terms), delay, theta, float(res @ res))


def predict(fit: TorqueFit, s: TorqueSet) -> np.ndarray:
    """Model torque (N, n) on one set."""
    cols = [t.columns(s) for t in fit.terms if t.n_params]
    pred = s.F0.copy()
    if cols:
        pred = pred + np.concatenate(cols, axis=2) @ fit.theta
    return shift(pred, s.t, fit.delay)


def fit_with(base_terms, base_delay, new: Term | None, sets) -> TorqueFit:
    """Refit with ``new`` added; its hyper-parameter (if any) searched on a grid by training cost."""
    if new is None:
        return fit_terms(base_terms, base_delay, sets)
    if new.effect == "sensor_delay":
        fits = [fit_terms(base_terms, d, sets) for d in DELAYS]
        best = min(fits, key=lambda f: f.cost)
        return TorqueFit(best.terms + (Term("sensor_delay", None, best.delay),), best.delay, best.theta, best.cost)
    if new.effect == "backlash":
        # play half-width on a grid (engagement BACKLASH_ENGAGE_FIRST), the engagement time on its grid, then the
        # half-width refined around the best
        fit = lambda h: fit_terms(tuple(base_terms) + (Term("backlash", new.joint, h),), base_delay, sets)
        best = min((fit((b, BACKLASH_ENGAGE_FIRST)) for b in BACKLASH_B), key=lambda f: f.cost)
        b = best.terms[-1].hyper[0]
        best = min([best] + [fit((b, te)) for te in BACKLASH_ENGAGE if te != BACKLASH_ENGAGE_FIRST], key=lambda f: f.cost)
        te = best.terms[-1].hyper[1]
        for step in (0.00125, 0.000625):
            best = min([best] + [fit((b + d, te)) for d in (-step, step) if b + d > 0], key=lambda f: f.cost)
            b = best.terms[-1].hyper[0]
        return best
    grid = {"stribeck_friction": STRIBECK_VS}.get(new.effect)
    if grid is not None:
        fits = [fit_terms(tuple(base_terms) + (Term(new.effect, new.joint, v),), base_delay, sets) for v in grid]
        return min(fits, key=lambda f: f.cost)
    return fit_terms(tuple(base_terms) + (new,), base_delay, sets)


def term_parameters(fit: TorqueFit, joint_names) -> dict:
    """``{label: {param: value}}`` of a fit."""
    out, k = {}, 0
    for t in fit.terms:
        names = t.param_names()
        d = {nm: float(fit.theta[k + i]) for i, nm in enumerate(names)}
        if t.effect == "stribeck_friction":
            d["vs [rad/s]"] = float(t.hyper)
        if t.effect == "sensor_delay":
            d["delay [s]"] = float(t.hyper)
        if t.effect == "backlash":
            b, te = backlash_hyper(t.hyper)
            d["b [rad]"], d["engagement [s]"] = b, te
        out[t.label(joint_names)] = d
        k += len(names)
    return out
