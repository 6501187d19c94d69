"""Torque data sets of the gap diagnosis and the equation-error fit of torque terms on them.

Along a measured motion the inverse dynamics of the nominal model plus effects is

$$ \\tau(t) = S_d\\big[\\tau_{rigid}(q, \\dot q, \\ddot q) + \\sum_e Y_e(q, \\dot q, \\ddot q; h_e)\\,\\theta_e\\big], $$

linear in every effect's coefficients ``theta_e`` once its few nonlinear hyper-parameters ``h_e``
(Stribeck velocity, sensor delay ``d`` of the shift operator ``S_d``) are fixed. With the nominal
identification (:mod:`._inertia`) ``tau_rigid = Y (pi_cad + delta)`` and ``delta`` is fitted with
the coefficients. So each refit is a bounded linear least-squares solve (warm start: the hyper-parameters of effects already in the
model are kept; only a new effect's are searched on a grid). The kinds of term are in
:mod:`._torque_terms`; the laws among them are :mod:`jflex.effects` effects (:mod:`._effect_term`).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import scipy.optimize as so

from ..._dynamics import rnea
from ..._sweep import flagged_vmap
from ...data._angle_log import VELOCITY_LAG_MIN, process_angle_log, propagated_noise, trimmed
from ...data._condition import CUTOFF_FACTOR as CUTOFF_FACTOR  # the torque terms' own low-pass reads it here
from ...data._signal import shift, zero_phase_lowpass



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
    Y: np.ndarray  # (N, n, 10 n) joint-torque regressor along the motion (see y_filtered)
    q_extra: np.ndarray
    extra_joints: tuple
    robot: object = None
    cutoff: float | None = None  # [Hz] of the parallel low-pass (None: the data came differentiated)
    noise: np.ndarray | None = None  # (n,) torque-residual noise std [N m] the processing predicts
    processing: dict = dataclasses.field(default_factory=dict)  # what was derived, for the report
    cache: dict = dataclasses.field(default_factory=dict)  # backlash torques, filtered columns
    # (N, n) 1 where a measured torque enters the fits and the gap, 0 where it does not (a clipping
    # sensor's samples, widened by the filter's reach); None: every sample enters
    weight: np.ndarray | None = None
    y_filtered: bool = False  # Y holds the regressor through the parallel filter (its raw copy dropped)

    def row_weights(self) -> np.ndarray:
        """(N, n) weights of the fits' rows: each joint's ``1 / scale`` times :attr:`weight`."""
        w = np.broadcast_to((1.0 / self.scale)[None, :], self.tau.shape)
        return w if self.weight is None else w * self.weight

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


ROW_BUCKET = 512  # samples: a batch's rows are padded to a multiple of this before a compiled call


def on_rows(fn, static: tuple, arrays) -> object:
    """``fn(*static, *arrays)`` of a compiled, row-wise (vmapped) function, with ``arrays`` padded
    along their first axis (the last row repeated) to a multiple of ROW_BUCKET and the outputs cut
    back to the rows given, as NumPy arrays. A compiled program is specialised to its shapes: real
    logs' records differ by a sample or two after resampling (1999, 2000), and each length compiled
    every batch anew (a jittered 7-joint log: 204 s against its uniform twin's 49 s)."""
    arrays = [np.asarray(a) for a in arrays]
    N = arrays[0].shape[0]
    M = max(-(-N // ROW_BUCKET) * ROW_BUCKET, ROW_BUCKET)
    if M > N:
        arrays = [np.concatenate([a, np.repeat(a[-1:], M - N, axis=0)]) for a in arrays]
    out = fn(*static, *(jax.device_put(a) for a in arrays))  # (jnp.asarray compiles a copy per shape)
    return jax.tree.map(lambda o: np.asarray(o)[:N], out)


# Row-wise programs with RNEA's checks as flags raised on the host (flagged_vmap), not eqx.error_if:
# JAX's persistent compilation cache stores no program that calls back into Python, and these
# hold most of a diagnosis' compilation.
_id_batch = flagged_vmap(lambda robot, a, b, c: rnea(robot, a, b, c), in_axes=(None, 0, 0, 0))


def _rigid_row(robot, a, b, c):
    """Inverse dynamics (n,) and regressor (n, 10 n) at one sample. The regressor is the Jacobian
    of RNEA in the inertial parameters (RNEA is linear in them): one JVP of the traversal compiles
    in a fraction of the time of the per-parameter regressor."""
    import equinox as eqx

    pi = robot.inertia.reshape(-1)
    f = lambda p: rnea(eqx.tree_at(lambda r: r.inertia, robot, p.reshape(robot.inertia.shape)), a, b, c)
    return f(pi), jax.jacfwd(f)(pi)


_rigid_batch = flagged_vmap(_rigid_row, in_axes=(None, 0, 0, 0))  # (N, n), (N, n, 10 n)


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
    angle noise (:func:`jflex.data._signal.motion_band`), the angles are low-passed at ``cutoff_hz``
    (``"auto"``: ``CUTOFF_FACTOR`` x that band) with a zero-phase Butterworth filter and
    differentiated, and the same filter is applied to the measured torques and to every model
    column (parallel filtering), optionally followed by keeping every ``decimate``-th sample. The
    noise the filtered residual keeps is predicted from the raw torque's spectrum just above the
    motion band (extrapolated flat into it and weighted by the filter) plus the angle noise
    propagated through the processing and the model (:func:`jflex.data._angle_log.process_angle_log`).

    A set that gave velocities without accelerations is processed the same way, its velocities
    low-passed (not the angles differentiated) before they are differentiated once. ``"auto"``
    chooses the cutoff per record from its own spectrum, inside (0, ``CUTOFF_LIMIT`` x Nyquist),
    with a named fallback (:func:`jflex.data.choose_cutoff`); stamps that are not uniform are
    resampled first (:func:`jflex.data.resample_uniform`; :func:`jflex.gap.load_case` has done so
    already for every reader)."""
    a = ds.arrays
    t, tau_raw = np.asarray(a["t"], float), np.asarray(a["tau"], float)
    valid = np.asarray(a["tau_valid"], bool) if "tau_valid" in a else None  # clipped samples masked
    # velocities without accelerations (the loader differentiated them, unfiltered, for the record)
    velocity_only = (getattr(ds, "conditioning", None) or {}).get("derivatives") == "velocity"
    if derivatives_given(ds) and not velocity_only:
        q, qd, qdd = a["q"], a["qd"], a["qdd"]
        F, Y = on_rows(_rigid_batch, (robot,), (q, qd, qdd))
        weight = None if valid is None else valid.astype(float)
        return TorqueSet(ds.name, t, q, qd, qdd, tau_raw, F, _spread(tau_raw, weight), Y,
                         a["q_extra"], ds.extra_joints, robot, weight=weight)
    rows = {"q": np.asarray(a["q"], float), "tau": tau_raw, "q_extra": np.asarray(a["q_extra"], float)}
    if velocity_only:
        rows["qd"] = np.asarray(a["qd"], float)
    if valid is not None:
        rows["tau_valid"] = valid.astype(float)
    resampled = bool(((getattr(ds, "conditioning", None) or {}).get("sampling") or {}).get("resampled"))
    log = process_angle_log(t, rows, ds.name, cutoff_hz=cutoff_hz, decimate=decimate, velocity_only=velocity_only,
                            resampled=resampled)
    F, Y = on_rows(_rigid_batch, (robot,), (log.q, log.qd, log.qdd))
    var_q = propagated_noise(log, lambda qk, qdk, qddk: on_rows(_id_batch, (robot,), (qk, qdk, qddk)) - F)
    sl, weight, edge = trimmed(log, ds.name, decimate)
    h, fc, lag, var_tau = log.h, log.cutoff, log.lag, log.torque_variance
    processing = {"angle_noise_rad": log.angle_noise.tolist(), "motion_band_hz": log.motion_band, "cutoff_hz": fc,
                  "decimate": int(decimate), "cutoff_method": log.cutoff_info["method"], "cutoff": log.cutoff_info,
                  "sampling": log.sampling, "velocity_lag_s": lag if abs(lag) > VELOCITY_LAG_MIN * h else 0.0,
                  "derivatives": "velocities filtered, then differentiated" if velocity_only else
                  "angles filtered, then differentiated twice", "trimmed_s": edge * h,
                  "torque_noise_nm": np.sqrt(var_tau).tolist(), "propagated_angle_noise_nm": np.sqrt(var_q).tolist()}
    if weight is not None:
        processing["masked_fraction"] = (1.0 - weight.mean(axis=0)).tolist()
    return TorqueSet(ds.name, log.t[sl], log.q[sl], log.qd[sl], log.qdd[sl], log.tau[sl], F[sl],
                     _spread(log.tau[sl], weight), Y[sl], log.rows["q_extra"][sl], ds.extra_joints, robot, cutoff=fc,
                     noise=np.sqrt(var_tau + var_q), processing=processing, weight=weight)


def _spread(tau, weight=None) -> np.ndarray:
    """(n,) std of the measured torque per joint over the samples that enter (``weight`` > 0)."""
    if weight is None:
        return np.maximum(tau.std(axis=0), 1e-9)
    out = np.empty(tau.shape[1])
    for j in range(tau.shape[1]):
        x = tau[weight[:, j] > 0, j]
        out[j] = x.std() if x.size > 1 else 0.0
    return np.maximum(out, 1e-9)


class TorqueTerm:
    """One effect on the torque side, placed at ``joint`` (index, or None) with its nonlinear
    hyper-parameter ``hyper`` held: ``columns`` (N, n, k) such that ``tau += columns @ theta``.

    The kinds (:mod:`._torque_terms`, and :class:`._effect_term.EffectTerm` for an effect a user
    gives) are frozen dataclasses with the fields ``joint`` and ``hyper`` and define ``effect`` (the
    name), ``columns``, ``param_names``; the rest has defaults here."""

    per_joint = True  # placed at a joint (else one for the whole robot)
    signature = ""  # what its residual looks like, for the report
    delay = None  # [s] the shift of the measurement this term stands for (a sensor's delay)

    @property
    def n_params(self) -> int:
        return len(self.param_names())

    def bounds(self):
        return [0.0] * self.n_params, [np.inf] * self.n_params

    def label(self, joint_names) -> str:
        return self.effect if self.joint is None else f"{self.effect}@{joint_names[self.joint]}"

    def parameters(self, theta) -> dict:
        """``{name: value}`` of the fitted coefficients and the held hyper-parameters."""
        return {nm: float(v) for nm, v in zip(self.param_names(), theta)}

    def search(self, base_terms, base_delay, sets, inertia=None) -> "TorqueFit":
        """The refit with this term added to ``base_terms``; a kind with a hyper-parameter searches it."""
        return fit_terms(tuple(base_terms) + (self,), base_delay, sets, inertia)

    def probes(self) -> tuple:
        """Terms whose columns a residual is correlated with before any refit (:mod:`._signatures`)."""
        return (self,)

    def signature_columns(self, s, fit) -> np.ndarray:
        return np.concatenate([term_columns(t, s) for t in self.probes()], axis=2)

    def contribute(self, parts, theta) -> None:
        """Add the fitted effect to a simulation model's parts (:class:`._effect_term.FamilyCoefficients`);
        the default: the effect acts on what a sensor reads, not on the motion, and is not simulated."""

    def implausible(self, theta, sets) -> str | None:
        """A sentence naming a fitted parameter (coefficient ``theta`` or held hyper-parameter) that
        lies outside the range a machine can have, given the training ``sets`` (their torque
        spread, rates, sample time), with its value and the range; None when all are plausible.
        Default: no range known."""
        return None


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


def _product(s: TorqueSet, key, make):
    """``s.cache[key]``, made by ``make()`` the first time."""
    if key not in s.cache:
        s.cache[key] = make()
    return s.cache[key]


def term_columns(term: "TorqueTerm", s: TorqueSet) -> np.ndarray:
    """(N, n, k) columns of ``term`` on ``s``, through the set's parallel filter (cached). On a
    filtered set, the per-sample arrays the term's ``columns`` put into the cache (its unfiltered
    copy, or a block several terms share: a family's columns at every joint) are dropped once its
    columns are filtered; a later term that needs one makes it again."""
    key = ("cols", term)
    if key not in s.cache:
        made = set(s.cache)
        cols = s.lp(term.columns(s))
        if s.cutoff is not None:
            # every fit reads only the filtered columns: the unfiltered copies of the tried terms (a
            # play's grid of widths, each a rigid-torque change at every joint; the families'
            # blocks) held 0.6 GB of a 5 kHz 6-joint log's 2.6 GB, besides their filtered twins.
            # Made again, they are the same: the computation is deterministic
            for k in set(s.cache) - made:
                kept = isinstance(k, tuple) and k[0] in ("cols", "lp")  # filtered columns
                if not kept and _per_sample(s.cache[k], len(s.t)):
                    del s.cache[k]
        s.cache[key] = cols
    return s.cache[key]


def _per_sample(v, rows: int) -> bool:
    """Whether a cache entry (an array or a tuple holding some) holds an array ``rows`` long (one
    per sample), not only a product's few numbers."""
    parts = v if isinstance(v, tuple) else (v,)
    return any(isinstance(x, np.ndarray) and x.ndim and x.shape[0] == rows for x in parts)


def _filtered(s: TorqueSet, name: str):
    X = getattr(s, name)
    if name == "Y" and s.y_filtered:
        return X
    out = _product(s, ("lp", name), lambda: s.lp(X.reshape(X.shape[0], -1)).reshape(X.shape))
    if name == "Y" and s.cutoff is not None:
        # the unfiltered regressor serves nothing once its filtered copy exists (every fit and the
        # floor's black box read that one): (N, n, 10 n) at 5 kHz is 90 MB a 6-joint record
        s.Y, s.y_filtered = out, True
    return out


def weighted_inertia_columns(s: TorqueSet):
    """``(Yw, Yw'Yw)``: the set's inertial columns through its parallel filter, rows normalised by
    its torque scale, as every fit sees them (cached)."""
    def make():
        Yw = (_filtered(s, "Y") * s.row_weights()[:, :, None]).reshape(s.tau.size, -1)
        return Yw, Yw.T @ Yw

    return _product(s, "Yw", make)


def _gram(terms, delay, s: TorqueSet, inertia):
    """Normal equations of one set, rows normalised by the set's torque scale: ``(G, b, y'y, rows)``
    over ``[delta (if inertia), theta]``. The delay advances the measurement (``tau(t + d)``), so
    the model's columns, and the Gram of the regressor, do not change with it. Built from
    per-term blocks kept with the set: the selection refits the same terms in many combinations,
    and the products over every sample, not the small solve, were its cost."""
    terms = [t for t in terms if t.n_params]
    w = s.row_weights()

    memo = []

    def y():
        # the target itself is not kept (one per delay tried, each as long as the record): only
        # its products are
        if not memo:
            memo.append(((shift(s.tau, s.t, -delay) - _filtered(s, "F0")) * w).ravel())
        return memo[0]

    yy = _product(s, ("yy", delay), lambda: float(y() @ y()))
    cols = {}

    def A(i):
        # weighted columns, made only where a product is missing (the filtered ones are cached)
        if i not in cols:
            c = term_columns(terms[i], s) * w[:, :, None]
            cols[i] = c.reshape(s.tau.size, c.shape[2])
        return cols[i]

    def AtA(i, j):
        a, b = terms[i], terms[j]
        if ("AA", b, a) in s.cache:
            return s.cache[("AA", b, a)].T
        return _product(s, ("AA", a, b), lambda: A(i).T @ A(j))

    m = len(terms)
    GA = np.block([[AtA(i, j) for j in range(m)] for i in range(m)]) if m else np.zeros((0, 0))
    bA = (np.concatenate([_product(s, ("Ay", terms[i], delay), lambda i=i: A(i).T @ y()) for i in range(m)])
          if m else np.zeros(0))
    rows = s.tau.size if s.weight is None else int(np.count_nonzero(s.weight))
    if inertia is None:
        return GA, bA, yy, rows
    Yw, YtY = weighted_inertia_columns(s)
    AtY = (np.concatenate([_product(s, ("AY", terms[i]), lambda i=i: A(i).T @ Yw) for i in range(m)])
           if m else np.zeros((0, Yw.shape[1])))
    G = np.block([[YtY, AtY.T], [AtY, GA]]) if GA.size else YtY
    Yty = _product(s, ("Yy", delay), lambda: Yw.T @ y())
    return G, np.concatenate([Yty, bA]), yy, rows


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
    lo, hi = np.concatenate(lo), np.concatenate(hi)
    x = _consistent(terms, _bounded_normal_solve(Gp, b, lo, hi), Gp, b, lo, hi, P)
    cost = float(yy - 2 * x @ b + x @ G @ x)
    cov = None
    if P:
        sig2 = max(cost, 0.0) / max(rows - p, 1)
        cov = sig2 * np.linalg.pinv(Gp, rcond=1e-13, hermitian=True)[:P, :P]
    return TorqueFit(terms, delay, x[P:], max(cost, 0.0), x[:P] if P else None, inertia, cov)


def _consistent(terms, x, G, b, lo, hi, P):
    """``x`` with the coefficients of each term that has a ``consistent(theta, metric)`` method (a
    payload: a rigid body's inertial parameters) moved into the set it allows, in the metric ``S``
    of the fit's own cost (the Schur complement of the other coefficients), and the other
    coefficients refitted around them within their bounds: a constrained fit, not a veto after it."""
    off = P
    for t in terms:
        if not t.n_params:
            continue
        sl = np.arange(off, off + t.n_params)
        off += t.n_params
        project = getattr(t, "consistent", None)
        if project is None:
            continue
        o = np.setdiff1d(np.arange(x.size), sl)
        Goo = G[np.ix_(o, o)]

        def metric(sl=sl, o=o, Goo=Goo):
            S = G[np.ix_(sl, sl)] - G[np.ix_(sl, o)] @ np.linalg.pinv(Goo, rcond=1e-13, hermitian=True) @ G[np.ix_(o, sl)]
            return 0.5 * (S + S.T)

        new = project(x[sl], metric)  # None: already in the set (the metric is then never formed)
        if new is None:
            continue
        x = x.copy()
        x[sl] = new
        if o.size:
            x[o] = _bounded_normal_solve(Goo, b[o] - G[np.ix_(o, sl)] @ new, lo[o], hi[o])
    return x


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


def fit_with(base_terms, base_delay, new, sets, inertia=None) -> TorqueFit:
    """Refit with the term ``new`` added (its kind searches its hyper-parameter, if any)."""
    if new is None:
        return fit_terms(base_terms, base_delay, sets, inertia)
    had = [set(s.cache) for s in sets]
    fit = new.search(base_terms, base_delay, sets, inertia)
    # the filtered columns of the hyper-parameters the search tried and left (a play's grid of
    # widths, each (N, n, 5) at 5 kHz) are dropped; their products with the other terms stay, and a
    # later search that tries them again makes them again, the same
    kept = set(fit.terms)
    for s, before in zip(sets, had):
        if s.cutoff is not None:
            for k in set(s.cache) - before:
                if isinstance(k, tuple) and k[0] == "cols" and k[1] not in kept:
                    del s.cache[k]
    return fit


def term_parameters(fit: TorqueFit, joint_names) -> dict:
    """``{label: {param: value}}`` of a fit."""
    out, k = {}, 0
    for t in fit.terms:
        out[t.label(joint_names)] = t.parameters(fit.theta[k:k + t.n_params])
        k += t.n_params
    return out
