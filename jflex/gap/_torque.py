"""Torque-side terms of the gap diagnosis: each effect as columns of an equation-error model.

Along a measured motion the inverse dynamics of the nominal model plus effects is

$$ \\tau(t) = S_d\\big[\\tau_{rigid}(q, \\dot q, \\ddot q) + \\sum_e Y_e(q, \\dot q, \\ddot q; h_e)\\,\\theta_e\\big], $$

linear in every effect's coefficients ``theta_e`` once its few nonlinear hyper-parameters ``h_e``
(Stribeck velocity, sensor delay ``d`` of the shift operator ``S_d``) are fixed. With the nominal
identification (:mod:`._inertia`) ``tau_rigid = Y (pi_cad + delta)`` and ``delta`` is fitted with
the coefficients. So each refit is a bounded linear least-squares solve (warm start: the hyper-parameters of effects already in the
model are kept; only a new effect's are searched on a grid). Each term's columns equal minus the
generalised force of the matching :mod:`jflex.effects` effect (checked in the tests).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import scipy.optimize as so

from .._dynamics import rnea
from .._errors import DataError
from ._effect_term import family_columns
from ..identify._signal import (angle_noise, band_noise_psd, filtered_derivatives, lowpass_power_gain,
                                motion_band, zero_phase_lowpass)

EPS_SIGN = 0.005  # [rad/s] width of the smooth sign used by every Coulomb-like term (dry friction is sharp)
# torque-side laws whose columns come from jflex.effects (the others act between the measurement and
# the rigid model: a sensor's delay, play between motor encoder and link, a link lagging its motor)
LAW_FAMILIES = ("viscous_friction", "coulomb_friction", "stribeck_friction", "rotor_inertia", "gravity_compensator",
                "payload")
STRIBECK_VS = (0.03, 0.06, 0.12, 0.25, 0.5)  # [rad/s] grid of Stribeck velocities
DELAYS = tuple(np.round(np.arange(0.001, 0.0605, 0.001), 4))  # [s] grid of sensor delays


@dataclasses.dataclass
class TorqueSet:
    """Precomputed quantities of one torque data set (numpy, (N, n) unless noted).

    ``q``, ``qd``, ``qdd`` are the motion the model sees (filtered and differentiated when the set
    gave angles only); ``tau`` is what the model is compared with: the measured torque, low-passed
    by the same filter ``lp`` as every model column (parallel filtering) when there is one."""

    name: str
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    F0: np.ndarray  # rigid inverse dynamics of the nominal (CAD) robot
    scale: np.ndarray  # (n,) std of the measured torque per joint
    Y: np.ndarray  # (N, n, 10 n) joint-torque regressor along the motion
    q_extra: np.ndarray
    extra_joints: tuple
    robot: object = None
    cutoff: float | None = None  # [Hz] of the parallel low-pass (None: the data came differentiated)
    noise: np.ndarray | None = None  # (n,) torque-residual noise std [N m] the processing predicts
    processing: dict = dataclasses.field(default_factory=dict)  # what was derived, for the report
    cache: dict = dataclasses.field(default_factory=dict)  # backlash torques, filtered columns

    @property
    def Ypay(self) -> np.ndarray:
        """(N, n, 10) regressor columns of the last link (a payload's parameters)."""
        n = self.q.shape[1]
        return self.Y[:, :, 10 * (n - 1):10 * n]

    def lp(self, X):
        """The parallel filter applied to a model quantity (N, ...) (identity without one)."""
        if self.cutoff is None:
            return X
        return zero_phase_lowpass(X, float(np.mean(np.diff(self.t))), self.cutoff)


@jax.jit
def _id_batch(robot, q, qd, qdd):
    return jax.vmap(lambda a, b, c: rnea(robot, a, b, c))(q, qd, qdd)


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


@jax.jit
def _rigid_batch(robot, q, qd, qdd):
    """Inverse dynamics (N, n) and regressor (N, n, 10 n) along a motion. The regressor is the
    Jacobian of RNEA in the inertial parameters (RNEA is linear in them): one JVP of the traversal
    compiles in a fraction of the time of the per-parameter regressor."""
    import equinox as eqx

    pi = robot.inertia.reshape(-1)

    def f(p, a, b, c):
        return rnea(eqx.tree_at(lambda r: r.inertia, robot, p.reshape(robot.inertia.shape)), a, b, c)

    F = jax.vmap(lambda a, b, c: f(pi, a, b, c))(q, qd, qdd)
    Y = jax.vmap(lambda a, b, c: jax.jacfwd(f)(pi, a, b, c))(q, qd, qdd)
    return F, Y


CUTOFF_FACTOR = 2.5  # the parallel low-pass sits at 2.5 x the motion's band (seed 003 3.2: 2-5 x)
NOISE_DRAWS = 4  # angle-noise redraws propagated through the processing and the model (noise floor)
NOISE_BAND = (1.5, 4.0)  # x the motion band: where the raw torque's noise level is read
EDGE_PERIODS = 2.0  # periods of the cutoff trimmed off each end of a filtered record (transients)


def derivatives_given(ds) -> bool:
    """Whether a torque set recorded its own rates and accelerations. The loader fills missing
    ones with central differences of ``q`` (bit for bit), which is how an angle-only log is told
    apart here."""
    a = ds.arrays
    return not np.array_equal(a["qd"], np.gradient(a["q"], a["t"], axis=0))


def torque_set(robot, ds, *, cutoff_hz="auto", decimate: int = 1) -> TorqueSet:
    """Precompute one torque data set (:class:`jflex.gap.Dataset`) for ``robot``.

    A set that gave angles only (a real log: encoder angles, quantised, and motor torques) is
    processed as for identification: the motion's band is read off the angle spectrum against the
    angle noise (:func:`jflex.identify.motion_band`), the angles are low-passed at ``cutoff_hz``
    (``"auto"``: ``CUTOFF_FACTOR`` x that band) with a zero-phase Butterworth filter and
    differentiated, and the same filter is applied to the measured torques and to every model
    column (parallel filtering), optionally followed by keeping every ``decimate``-th sample. The
    noise the filtered residual keeps is predicted from the raw torque's spectrum just above the
    motion band (extrapolated flat into it and weighted by the filter) plus the angle noise
    propagated through the processing and the model (``NOISE_DRAWS`` redraws)."""
    a = ds.arrays
    t, tau_raw = np.asarray(a["t"], float), np.asarray(a["tau"], float)
    if derivatives_given(ds):
        q, qd, qdd = a["q"], a["qd"], a["qdd"]
        F, Y = (np.asarray(v) for v in _rigid_batch(robot, jnp.asarray(q), jnp.asarray(qd), jnp.asarray(qdd)))
        return TorqueSet(ds.name, t, q, qd, qdd, tau_raw, F, np.maximum(tau_raw.std(axis=0), 1e-9), Y,
                         a["q_extra"], ds.extra_joints, robot)
    dt = np.diff(t)
    h = float(dt.mean())
    if np.max(np.abs(dt - h)) > 0.01 * h:
        raise DataError(f"{ds.name}: field 't': a torque set with angles only (no qd/qdd) needs uniform sampling "
                        f"(steps vary by {100 * np.max(np.abs(dt - h)) / h:.1f} %, more than 1 %)")
    sig_q = angle_noise(a["q"])
    f_m = motion_band(a["q"], h, sig_q)
    fc = CUTOFF_FACTOR * f_m if cutoff_hz in (None, "auto") else float(cutoff_hz)
    nyq = 0.5 / (h * decimate)
    if not 0 < fc < 0.9 * nyq:
        raise DataError(f"{ds.name}: the low-pass cutoff {fc:.3g} Hz must lie below 0.9 x the Nyquist frequency "
                        f"{nyq:.3g} Hz{' after decimation' if decimate > 1 else ''} (options.filter_cutoff_hz, options.decimate)")
    q, qd, qdd = filtered_derivatives(a["q"], h, fc)
    tau = zero_phase_lowpass(tau_raw, h, fc)
    # noise of the filtered torque: the raw torque's PSD above the motion (measured), extrapolated
    # flat below 1.5 f_m, times the filter's power gain
    level, f, P = band_noise_psd(tau_raw, h, NOISE_BAND[0] * f_m, NOISE_BAND[1] * f_m)
    g = lowpass_power_gain(f, h, fc)
    df = f[1] - f[0]
    hi = f > NOISE_BAND[0] * f_m
    var_tau = (P[hi] * g[hi, None]).sum(axis=0) * df + level * (g[~hi].sum() * df)
    rng = np.random.default_rng(0)
    F, Y = (np.asarray(v) for v in _rigid_batch(robot, jnp.asarray(q), jnp.asarray(qd), jnp.asarray(qdd)))
    dev = []
    for _ in range(NOISE_DRAWS):
        qk, qdk, qddk = filtered_derivatives(a["q"] + sig_q * rng.standard_normal(a["q"].shape), h, fc)
        dev.append(np.asarray(_id_batch(robot, jnp.asarray(qk), jnp.asarray(qdk), jnp.asarray(qddk))) - F)
    var_q = np.mean([d.var(axis=0) for d in dev], axis=0)
    k = int(decimate)
    # the filter's start and end transients (zero-phase: both ends) are cut off the record
    edge = int(np.ceil(EDGE_PERIODS / fc / h))
    if t.size - 2 * edge < 20 * k:
        raise DataError(f"{ds.name}: field 't': the record ({t[-1] - t[0]:.3g} s) is too short for its low-pass at "
                        f"{fc:.3g} Hz, whose transients take {edge * h:.3g} s at each end")
    sl = slice(edge, t.size - edge, k)
    processing = {"angle_noise_rad": sig_q.tolist(), "motion_band_hz": f_m, "cutoff_hz": fc, "decimate": k,
                  "trimmed_s": edge * h,
                  "torque_noise_nm": np.sqrt(var_tau).tolist(), "propagated_angle_noise_nm": np.sqrt(var_q).tolist()}
    return TorqueSet(ds.name, t[sl], q[sl], qd[sl], qdd[sl], tau[sl], F[sl], np.maximum(tau[sl].std(axis=0), 1e-9), Y[sl],
                     a["q_extra"][sl], ds.extra_joints, robot, cutoff=fc, noise=np.sqrt(var_tau + var_q),
                     processing=processing)


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
        Fa = np.asarray(_id_batch(s.robot, jnp.asarray(ql), jnp.asarray(qdl), jnp.asarray(s.qdd)))
        cols = [Fa - s.F0]
        for w in BACKLASH_PULSES:
            qdd = s.qdd.copy()
            qdd[:, j] = np.gradient(first_order_zero_phase(qdl[:, j], s.t, w), s.t)
            cols.append(np.asarray(_id_batch(s.robot, jnp.asarray(ql), jnp.asarray(qdl), jnp.asarray(qdd))) - Fa)
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


def link_lag_column(s: TorqueSet, j: int, lag) -> np.ndarray:
    """(N, n) change of the rigid torques when the link of joint ``j`` lags the measured angle by
    ``lag`` (N,) per unit of it, to first order: minus RNEA's directional derivative along
    ``e_j (lag, d lag/dt, d2 lag/dt2)``."""
    lagd = np.gradient(lag, s.t)
    d = [np.zeros_like(s.q) for _ in range(3)]
    for k, v in enumerate((lag, lagd, np.gradient(lagd, s.t))):
        d[k][:, j] = v
    return -np.asarray(_jvp_batch(s.robot, *[jnp.asarray(a) for a in (s.q, s.qd, s.qdd, *d)]))


@jax.jit
def _jvp_batch(robot, q, qd, qdd, dq, dqd, dqdd):
    f = lambda a, b, c: rnea(robot, a, b, c)
    return jax.vmap(lambda *x: jax.jvp(f, x[:3], x[3:])[1])(q, qd, qdd, dq, dqd, dqdd)


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
        if self.effect == "backlash" and is_loaded(self.hyper):
            return 2
        return {"stribeck_friction": 2, "gravity_compensator": 4, "payload": 10, "sensor_delay": 0, "joint_flexibility": 1,
                "backlash": 1 + len(BACKLASH_PULSES)}.get(self.effect, 1)

    def bounds(self):
        lo = {"gravity_compensator": [-np.inf] * 4, "payload": [0.0] + [-np.inf] * 9}.get(
            self.effect, [0.0] * self.n_params)
        return lo, [np.inf] * self.n_params

    def param_names(self):
        if self.effect == "backlash" and is_loaded(self.hyper):
            return ["compliance 1/k [rad/(N m)]", "b [rad]"]
        return {
            "viscous_friction": ["Fv [N m s/rad]"], "coulomb_friction": ["Fc [N m]"],
            "stribeck_friction": ["Fc [N m]", "Fs-Fc [N m]"], "rotor_inertia": ["Ia [kg m^2]"],
            "joint_flexibility": ["compliance 1/k [rad/(N m)]"],
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
        if e in LAW_FAMILIES:
            # the law of jflex.effects itself: its inverse-dynamics Jacobian in the coefficients
            key = ("family", e, self.hyper)
            if key not in s.cache:
                args = [jnp.asarray(a) for a in (s.q, s.qd, s.qdd)]
                s.cache[key] = family_columns(s.robot, e, self.hyper, *args)
            cols, per = s.cache[key]
            out[:] = cols[:, :, per(0 if j is None else j)]
            if e == "stribeck_friction":
                out[:, :, 0] += out[:, :, 1]  # [Fc, Fs] -> [Fc, Fs - Fc]
        elif e == "joint_flexibility":
            out[:, :, 0] = compliance_column(s, j)
        elif e == "backlash" and is_loaded(self.hyper):
            out[:, :, :] = loaded_backlash_torque(s, j, self.hyper[1])
        elif e == "backlash":
            # motor-side encoder; the link follows through the play (hyper = (half-width, engagement))
            out[:, :, :] = backlash_torque(s, j, self.hyper)
        return out

    def label(self, joint_names) -> str:
        return self.effect if self.joint is None else f"{self.effect}@{joint_names[self.joint]}"


@dataclasses.dataclass
class TorqueFit:
    """Fitted torque terms: coefficients ``theta`` of ``terms``, the sensor ``delay`` [s] and, when
    the inertial parameters were refitted, ``delta`` (10 n) from CAD with its ``prior``."""

    terms: tuple
    delay: float
    theta: np.ndarray
    cost: float
    delta: np.ndarray | None = None
    prior: object = None
    cov_delta: np.ndarray | None = None  # (10 n, 10 n) covariance of delta (bounds inactive)


def term_columns(term: Term, s: TorqueSet) -> np.ndarray:
    """(N, n, k) columns of ``term`` on ``s``, through the set's parallel filter (cached)."""
    key = ("cols", term)
    if key not in s.cache:
        s.cache[key] = s.lp(term.columns(s))
    return s.cache[key]


def _filtered(s: TorqueSet, name: str):
    key = ("lp", name)
    if key not in s.cache:
        X = getattr(s, name)
        s.cache[key] = s.lp(X.reshape(X.shape[0], -1)).reshape(X.shape)
    return s.cache[key]


def _gram(terms, delay, s: TorqueSet, inertia):
    """Normal equations of one set, rows normalised by the set's torque scale: ``(G, b, y'y, rows)``
    over ``[delta (if inertia), theta]``. The delay advances the measurement (``tau(t + d)``), so
    the model's columns, and the Gram of the regressor, do not change with it."""
    w = 1.0 / s.scale
    cols = [term_columns(t, s) for t in terms if t.n_params]
    A = (np.concatenate(cols, axis=2) if cols else np.zeros(s.q.shape + (0,))) * w[None, :, None]
    A = A.reshape(s.tau.size, A.shape[2])
    y = ((shift(s.tau, s.t, -delay) - _filtered(s, "F0")) * w[None, :]).ravel()
    if inertia is None:
        return A.T @ A, A.T @ y, float(y @ y), y.size
    if "Yw" not in s.cache:
        Yw = (_filtered(s, "Y") * w[None, :, None]).reshape(y.size, -1)
        s.cache["Yw"] = (Yw, Yw.T @ Yw)
    Yw, YtY = s.cache["Yw"]
    AtY = A.T @ Yw
    G = np.block([[YtY, AtY.T], [AtY, A.T @ A]])
    return G, np.concatenate([Yw.T @ y, A.T @ y]), float(y @ y), y.size


def _bounded_normal_solve(G, b, lo, hi):
    """``min x'Gx - 2 b'x`` within bounds, through the Cholesky factor of the column-scaled ``G``
    (a small square problem whatever the number of samples)."""
    d = np.sqrt(np.maximum(np.diag(G), 0.0))
    d = np.where(d > 1e-12 * max(d.max(), 1e-300), d, 1.0)
    Gs = G / d[:, None] / d[None, :]
    Gs[np.diag_indices_from(Gs)] += 1e-12
    L = np.linalg.cholesky(Gs)
    z = np.linalg.solve(L, b / d)
    if np.all(np.isinf(lo)) and np.all(np.isinf(hi)):
        return np.linalg.solve(L.T, z) / d
    r = so.lsq_linear(L.T, z, bounds=(lo * d, hi * d), method="bvls")
    return r.x / d


def fit_terms(terms, delay, sets, inertia=None) -> TorqueFit:
    """Bounded least squares of the terms' coefficients on the torque sets (channel-normalised),
    with the inertial parameters' change from CAD when ``inertia`` (:class:`._inertia.InertiaPrior`)
    is given."""
    terms = tuple(terms)
    P = inertia.size if inertia is not None else 0
    G = b = None
    yy, rows = 0.0, 0
    for s in sets:
        g, bb, y2, m = _gram(terms, delay, s, inertia)
        G, b = (g, bb) if G is None else (G + g, b + bb)
        yy, rows = yy + y2, rows + m
    p = G.shape[0]
    if p == 0:
        return TorqueFit(terms, delay, np.zeros(0), yy)
    lo = [np.concatenate([t.bounds()[0] for t in terms if t.n_params] or [np.zeros(0)])]
    hi = [np.concatenate([t.bounds()[1] for t in terms if t.n_params] or [np.zeros(0)])]
    Gp = G.copy()
    if P:
        l, h = inertia.bounds()
        lo, hi = [l] + lo, [h] + hi
        Gp[np.arange(P), np.arange(P)] += inertia.penalty()
    x = _bounded_normal_solve(Gp, b, np.concatenate(lo), np.concatenate(hi))
    cost = float(yy - 2 * x @ b + x @ G @ x)
    cov = None
    if P:
        sig2 = max(cost, 0.0) / max(rows - p, 1)
        cov = sig2 * np.linalg.pinv(Gp, rcond=1e-13, hermitian=True)[:P, :P]
    return TorqueFit(terms, delay, x[P:], max(cost, 0.0), x[:P] if P else None, inertia, cov)


def predict(fit: TorqueFit, s: TorqueSet) -> np.ndarray:
    """Model torque (N, n) on one set (through its parallel filter, then delayed)."""
    cols = [term_columns(t, s) for t in fit.terms if t.n_params]
    pred = _filtered(s, "F0").copy()
    if cols:
        pred = pred + np.concatenate(cols, axis=2) @ fit.theta
    if fit.delta is not None:
        pred = pred + _filtered(s, "Y") @ fit.delta
    return shift(pred, s.t, fit.delay)


def inertia_rank(sets) -> int:
    """Number of inertial parameter combinations the sets excite (the base parameters they see)."""
    G = sum(s.cache["Yw"][1] for s in sets if "Yw" in s.cache)
    if np.ndim(G) == 0:
        return 0
    d = np.sqrt(np.maximum(np.diag(G), 1e-300))
    ev = np.linalg.eigvalsh(G / d[:, None] / d[None, :])
    return int(np.sum(ev > 1e-10 * ev.max()))


def with_inertia_sigma(fit: TorqueFit, sets) -> float:
    """Normalised RMS training residual of a fit: the noise level its inertial prior is weighed against."""
    rows = sum(s.tau.size for s in sets)
    return float(np.sqrt(fit.cost / max(rows, 1)))


def fit_with(base_terms, base_delay, new: Term | None, sets, inertia=None) -> TorqueFit:
    """Refit with ``new`` added; its hyper-parameter (if any) searched on a grid by training cost."""
    if new is None:
        return fit_terms(base_terms, base_delay, sets, inertia)
    if new.effect == "sensor_delay":
        fits = [fit_terms(base_terms, d, sets, inertia) for d in DELAYS]
        best = min(fits, key=lambda f: f.cost)
        return dataclasses.replace(best, terms=best.terms + (Term("sensor_delay", None, best.delay),))
    if new.effect == "backlash":
        # the kinematic play and the loaded gear free different numbers of coefficients: the better
        # of the two by the information criterion
        rows = sum(s.tau.size for s in sets)
        bic = lambda f: rows * np.log(max(f.cost, 1e-300)) + f.terms[-1].n_params * np.log(rows)
        return min((fit_play_backlash(base_terms, base_delay, new.joint, sets, inertia),
                    fit_loaded_backlash(base_terms, base_delay, new.joint, sets, inertia)), key=bic)
    grid = {"stribeck_friction": STRIBECK_VS}.get(new.effect)
    if grid is not None:
        fits = [fit_terms(tuple(base_terms) + (Term(new.effect, new.joint, v),), base_delay, sets, inertia) for v in grid]
        return min(fits, key=lambda f: f.cost)
    return fit_terms(tuple(base_terms) + (new,), base_delay, sets, inertia)


def fit_play_backlash(base_terms, base_delay, j, sets, inertia=None) -> TorqueFit:
    """Kinematic play at joint ``j`` (:func:`backlash_torque`): the half-width on a grid (engagement
    BACKLASH_ENGAGE_FIRST), the engagement time on its grid, then the half-width refined around the best."""
    fit = lambda h: fit_terms(tuple(base_terms) + (Term("backlash", j, h),), base_delay, sets, inertia)
    best = min((fit((b, BACKLASH_ENGAGE_FIRST)) for b in BACKLASH_B), key=lambda f: f.cost)
    b = best.terms[-1].hyper[0]
    best = min([best] + [fit((b, te)) for te in BACKLASH_ENGAGE if te != BACKLASH_ENGAGE_FIRST], key=lambda f: f.cost)
    te = best.terms[-1].hyper[1]
    for step in (0.00125, 0.000625):
        best = min([best] + [fit((b + d, te)) for d in (-step, step) if b + d > 0], key=lambda f: f.cost)
        b = best.terms[-1].hyper[0]
    return best


def fit_loaded_backlash(base_terms, base_delay, j, sets, inertia=None) -> TorqueFit:
    """A loaded gear with play at joint ``j`` (:func:`loaded_backlash_torque`), its sign width on a grid."""
    fits = (fit_terms(tuple(base_terms) + (Term("backlash", j, (LOADED, w)),), base_delay, sets, inertia)
            for w in BACKLASH_SIGN_WIDTHS)
    return min(fits, key=lambda f: f.cost)


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
        if t.effect == "backlash" and is_loaded(t.hyper):
            d["sign width [x std(tau)]"] = float(t.hyper[1])
        elif t.effect == "backlash":
            b, te = backlash_hyper(t.hyper)
            d["b [rad]"], d["engagement [s]"] = b, te
        out[t.label(joint_names)] = d
        k += len(names)
    return out
