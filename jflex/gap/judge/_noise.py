"""The noise floor of each validation data set: the NRMSE [%] that measurement noise alone would
leave (from repeated records, what an angle-only log's processing predicts, or the residual's
high-frequency content)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..frequency import _model as L
from ..torque._set import _filtered, _product

if TYPE_CHECKING:
    from ..case._case import Case
    from .._problem import Problem

def robust_sigma(x):
    x = np.asarray(x).ravel()
    return 1.4826 * np.median(np.abs(x - np.median(x)))


def repeats_factor(rep, x) -> float:
    """sqrt(R) when the record ``x`` is the mean of its ``R`` repeats (its noise is that of one
    repeat over sqrt(R)), else 1 (a record of its own)."""
    R = rep.shape[0]
    if R > 1 and np.allclose(rep.mean(axis=0), x, rtol=1e-9, atol=1e-12 * float(np.max(np.abs(x)) or 1.0)):
        return float(np.sqrt(R))
    return 1.0


def noise_floor(problem: Problem, ev: dict, case: Case, sources: dict | None = None,
                details: dict | None = None) -> dict:
    """NRMSE [%] that noise alone leaves, per validation data set; never estimated from a candidate
    model's residual (a model error a candidate does not hold would then count as noise).

    Torque (the gap's measure: the residual energy over the torque-signal energy pooled over the
    joints, channels left out of the gap excluded): from ``tau_repeats`` when recorded (over
    sqrt(R) when ``tau`` is their mean); else, when the motion is periodic (an excitation
    trajectory repeated, as identification logs are), from the scatter of the torque between
    periods (:func:`periodic_noise`); else from split-half cross-validation of a flexible
    black-box model of the nominal residual (:func:`black_box_noise`: what a smooth function of
    the motion cannot predict on held-out samples, an upper bound of the noise that does not count
    structured model error).
    FRF: ``H_repeats`` when recorded (likewise), else the residual's second difference along
    frequency. Modal tables: :func:`modal_floor`.
    Output-error (tip) sets: ``y_repeats`` when recorded, else per channel the smaller of the
    residual's second-difference estimate and the record's own fourth difference,
    ``MAD(d4 y) / sqrt(70)`` (a nominal simulation that drifts or runs away fast leaves
    high-frequency content in the residual, not in the record; smooth motion barely enters d4).
    ``sources``: optional mapping filled with the method used per data set; ``details``: optional
    mapping filled per data set with ``method``, ``floor``, its 95 % interval ``low``/``high``
    (chi-square on the variance estimate, ``dof`` effective degrees of freedom), ``channels``
    (each channel's floor [%]), and ``failed`` with ``reason`` when the estimate is unusable (0,
    not finite, or at least a trivial model's gap, 100 %): the floor is then unknown (reported 0).
    """
    out = {}
    src = {} if sources is None else sources
    det = {} if details is None else details
    by_name = {d.name: d for d in case.datasets}
    for name, r in ev.items():
        d = by_name[name]
        info = {}
        if r["kind"] == "torque":
            s = next(s for s in problem.tval if s.name == name)
            m = problem.included(name) if hasattr(problem, "included") else np.ones(s.scale.shape, bool)
            if "tau_repeats" in d.arrays:
                rep = d.arrays["tau_repeats"]
                if s.cutoff is None:
                    src[name] = "propagated angle noise" if d.kind == "response" else "tau_repeats"
                else:
                    # repeats of raw torques through the same low-pass as the data
                    rep = np.stack([s.lp(r_)[::s.processing.get("decimate", 1)] for r_ in rep])
                    src[name] = "tau_repeats (filtered)"
                k = repeats_factor(d.arrays["tau_repeats"], d.arrays["tau"])
                sig = rep.std(axis=0, ddof=1).mean(axis=0) / k
                dof = np.full(sig.shape, float((rep.shape[0] - 1) * rep.shape[1]))
            else:
                per = periodic_noise(s.t, s.q, s.tau, m)
                if per is not None:
                    sig, dof, info = per
                    prop = _repeating_processing_error(s, m, sig)
                    sig = np.sqrt(sig**2 + prop**2)
                    info["processing_nm"] = prop.tolist()
                    src[name] = (f"scatter between periods ({info['periods']} periods of {info['period_s']:.4g} s"
                                 f"{', linear drift cancelled' if info['drift_cancelled'] else ''}"
                                 f"{', with the processing error' if np.any(prop > 0) else ''})")
                else:
                    sig, dof, info = black_box_noise(s, r["resid"] * s.scale, m)
                    for k in ("base_only", "angle_series", "rigid_body", "history", "unpredicted"):
                        info[k] = [problem.names[j] for j in info[k]]
                    src[name] = "black-box split-half cross-validation (upper bound)"
            out[name], info = _pooled(sig, dof, s.scale, m, problem.names, info)
        elif r["kind"] == "response":
            # output error: white measurement noise on y, the same estimates on the residual
            s = next(s for s in problem.rval if s.name == name)
            if "y_repeats" in d.arrays:
                rep = d.arrays["y_repeats"]
                sig = rep.std(axis=0, ddof=1).mean(axis=0) / s.scale / repeats_factor(rep, d.arrays["y"])
                src[name] = "y_repeats"
            else:
                e = r["resid"]
                d2 = e[2:] - 2 * e[1:-1] + e[:-2]
                s2 = np.array([robust_sigma(d2[:, j]) / np.sqrt(6) for j in range(e.shape[1])])
                y = s.y / s.scale
                d4 = y[4:] - 4 * y[3:-1] + 6 * y[2:-2] - 4 * y[1:-3] + y[:-4]
                s4 = np.array([robust_sigma(d4[:, j]) / np.sqrt(70) for j in range(y.shape[1])])
                sig = np.minimum(s2, s4)
                src[name] = ("residual second difference" if np.sum(s2**2) <= np.sum(s4**2) else
                             "record fourth difference")
            out[name] = float(np.sqrt(np.mean(sig**2)) * 100)
            info = dict(channels={c: float(v * 100) for c, v in zip(s.channels, sig)})
        elif r["kind"] == "frf":
            out[name], src[name] = frf_floor(d.arrays, r["err"])
        else:
            out[name], src[name] = modal_floor(case, d.arrays.get("zeta"))
        v = out[name]
        info = dict(info, method=src[name], floor=float(v) if np.isfinite(v) else None)
        info.setdefault("low", info["floor"])
        info.setdefault("high", info["floor"])
        if not np.isfinite(v) or v <= FLOOR_MIN or v >= TRIVIAL_GAP:
            info.update(failed=True, reason=("not a finite number" if not np.isfinite(v) else
                                             "zero: the estimate saw no noise at all" if v <= FLOOR_MIN else
                                             f"{v:.3g} %, at least the gap of a model that predicts the mean (100 %)"),
                        low=None, high=None)
            out[name] = 0.0
        else:
            info["failed"] = False
        det[name] = info
    return out


FLOOR_MIN = 1e-9  # [%] a floor at or below this saw no noise: failed
TRIVIAL_GAP = 100.0  # [%] the NRMSE of predicting each channel by its mean: a floor at or above it failed
CONFIDENCE = 0.95  # of the floor's interval (chi-square on the variance estimate)


def _pooled(sig, dof, scale, m, names, info):
    """The set's floor [%] from per-channel noise ``sig`` [N m] with ``dof`` degrees of freedom:
    noise energy over torque-signal energy of the included channels ``m`` (the gap's measure), its
    interval (Satterthwaite's degrees of freedom of the pooled variance, chi-square interval)."""
    from scipy.stats import chi2

    sig, dof, scale = (np.asarray(v, float) for v in (sig, dof, scale))
    w = np.where(m, 1.0, 0.0)
    var = np.sum(w * sig**2)
    en = np.sum(w * scale**2)
    floor = float(np.sqrt(var / en) * 100) if en > 0 else float("nan")
    parts = w * sig**2
    nu = float(var**2 / np.sum(np.where(m, parts**2 / np.maximum(dof, 1.0), 0.0))) if var > 0 else 0.0
    info = dict(info, dof=nu, channels={names[j]: float(sig[j] / scale[j] * 100) for j in range(len(names)) if m[j]},
                channel_dof={names[j]: float(dof[j]) for j in range(len(names)) if m[j]})
    if nu >= 1 and np.isfinite(floor):
        a = 1 - CONFIDENCE
        info["low"] = float(floor * np.sqrt(nu / chi2.ppf(1 - a / 2, nu)))
        info["high"] = float(floor * np.sqrt(nu / chi2.ppf(a / 2, nu)))
    return floor, info


def effective_samples(x, extra_lags=()) -> float:
    """Effective number of independent samples of the variance of ``x`` (N,): ``N / sum rho_k^2``
    (the variance of a Gaussian process's sample variance, Bartlett), the autocorrelation summed
    over the short lags until it falls inside its noise and at ``extra_lags`` (known correlations)."""
    x = np.asarray(x, float) - np.mean(x)
    N = len(x)
    if N < 4 or not np.any(x):
        return float(max(N, 1))
    F = np.fft.rfft(x, 2 * N)
    ac = np.fft.irfft(np.abs(F) ** 2)[:N]
    ac = ac / ac[0]
    lim = 2.0 / np.sqrt(N)
    k = int(np.argmax(np.abs(ac[1:]) < lim)) + 1 if np.any(np.abs(ac[1:]) < lim) else N // 4
    tot = 1.0 + 2.0 * np.sum(ac[1:min(2 * k, N // 4) + 1] ** 2)
    tot += 2.0 * sum(ac[L] ** 2 for L in extra_lags if 2 * k < L < N)
    return float(N / tot)


REPEAT_TOL = 0.02  # the angles repeat from period to period within 2 % of their spread
PERIOD_ACF = 0.9  # the angles' autocorrelation at the period
PERIOD_DIP = 0.5  # ... which has fallen below this before it (the motion left its start)
PERIOD_SEARCH = 0.01  # the closest repeat is sought within 1 % of the lag of that peak


def find_period(q) -> int | None:
    """The period of a motion (N, n) in samples: the first peak of the angles' autocorrelation
    (pooled over the moving joints), after it has fallen below PERIOD_DIP, above PERIOD_ACF at which every moving joint's angle repeats
    within REPEAT_TOL of its spread (the closest repeat within PERIOD_SEARCH of the peak's lag), with at least
    two periods in the record; None when the motion is not periodic."""
    x = np.asarray(q, float)
    x = x - x.mean(axis=0)
    sd = x.std(axis=0)
    mv = sd > 1e-6 * max(float(sd.max()), 1e-300)
    if not np.any(mv):
        return None
    x, sd = x[:, mv] / sd[mv], sd[mv]
    N = len(x)
    F = np.fft.rfft(x, 2 * N, axis=0)
    ac = np.fft.irfft(np.abs(F) ** 2, axis=0)[:N].sum(axis=1)
    ac = ac / ac[0] * N / np.maximum(N - np.arange(N), 1)

    def rep(k):
        return float(np.max(np.sqrt(np.mean((x[k:] - x[:-k]) ** 2, axis=0))))

    # a period is a return after the motion moved away from itself: the search starts once the
    # autocorrelation has fallen below PERIOD_DIP (a smooth motion sampled fast, whose unbiased
    # autocorrelation creeps over 1 in its first lags, otherwise "repeats" every few samples: a
    # UR5 log at 500 Hz read as 890 periods of 6 ms, its floor 30 x below the noise)
    below = np.flatnonzero(ac[: N // 2 + 1] < PERIOD_DIP)
    if below.size == 0:
        return None
    for k in range(max(2, int(below[0])), N // 2 + 1):
        if ac[k] >= PERIOD_ACF and ac[k] >= ac[k - 1] and ac[k] >= ac[min(k + 1, N - 1)]:
            # the unbiased autocorrelation's peak leans a few samples off the period of a smooth
            # motion sampled fast (3003 for 3000 at 500 Hz): the closest repeat is sought around it
            w = max(1, int(PERIOD_SEARCH * k))
            best = min((kk for kk in range(k - w, k + w + 1) if 1 <= kk <= N // 2), key=rep)
            if rep(best) <= REPEAT_TOL:
                return best
    return None


def _repeating_processing_error(s, m, sig) -> np.ndarray:
    """Per channel [N m], the error of filtering and differentiating a periodic record's angles
    that repeats with the period (an encoder's quantisation of a motion that repeats exactly
    repeats too): it cancels out of the scatter between periods but stays in the gap. The whole
    processing error is predicted by propagating the angle noise through the processing and the
    model (``propagated_angle_noise_nm`` of the set's processing); the part that does not repeat
    shows as the scatter between periods of the model's own torque along the processed motion,
    and is in the floor already."""
    prop = np.asarray(s.processing.get("propagated_angle_noise_nm", np.zeros_like(sig)), float)
    if not np.any(prop > 0):
        return np.zeros_like(sig)
    own = periodic_noise(s.t, s.q, _filtered(s, "F0") if hasattr(s, "cache") else s.F0, m)
    spread = own[0] if own is not None else np.zeros_like(prop)
    return np.sqrt(np.maximum(prop**2 - spread**2, 0.0))


def periodic_noise(t, q, tau, m):
    """Per-channel torque noise [N m] of a periodic record from the scatter between its periods:
    with three periods or more the second difference across periods, ``tau(t + 2P) - 2 tau(t + P)
    + tau(t)`` (variance 6 sigma^2; a drift linear in time cancels), else the first (2 sigma^2).
    Returns ``(sigma, dof, info)`` or None when the motion is not periodic (:func:`find_period`)."""
    k = find_period(q)
    if k is None:
        return None
    tau = np.asarray(tau, float)
    N = len(tau)
    P = N // k
    if P >= 3:
        d, c, lags = tau[2 * k:] - 2 * tau[k:-k] + tau[:-2 * k], 6.0, (k, 2 * k)
    else:
        d, c, lags = tau[k:] - tau[:-k], 2.0, (k,)
    sig = np.sqrt(np.mean(d**2, axis=0) / c)
    dof = np.array([effective_samples(d[:, j], lags) if m[j] else 1.0 for j in range(tau.shape[1])])
    h = float(np.mean(np.diff(t)))
    return sig, dof, dict(period_s=k * h, periods=int(P), drift_cancelled=P >= 3)


BLACK_BOX_BLOCKS = 32  # contiguous blocks, alternately held out (split-half cross-validation)
BLACK_BOX_FEATURES = 200  # random Fourier features of the motion, at most
# per joint: cosine series of these lengths in the joint's angle over its range, one model each
# (a series too long for the data chases the held-out blocks' edges, one too short misses a fast
# ripple; the data say which, as for the other models, on held-out blocks)
BLACK_BOX_HARMONICS = (8, 16, 32)
UNPREDICTED = 0.95  # a channel whose held-out bound keeps this share of its own residual's RMS


RIDGE_GRID = np.geomspace(1e-8, 1.0, 17)  # penalties, relative to the largest eigenvalue of the Gram


class _Moments:
    """Per-block sums of a feature matrix ``A`` (N, p) and targets ``Y`` (N, k) (counts, sums, Gram
    ``A_b^T A_b``, ``A_b^T Y_b``, ``sum Y_b^2``): every ridge fit and held-out error of the
    block cross-validation below is a sum over blocks of these, so the samples are read once
    however many models, folds and penalties are tried."""

    def __init__(self, A, Y, ids, nblk):
        sums = []
        for b in range(nblk):  # one block's rows at a time: never a second copy of A
            a, y = A[ids == b], Y[ids == b]
            sums.append((len(a), a.sum(axis=0), y.sum(axis=0), a.T @ a, a.T @ y, np.sum(y**2, axis=0)))
        n, sA, sY, G, C, yy = zip(*sums)
        self.n, self.sA, self.sY = np.array(n, float), np.stack(sA), np.stack(sY)
        self.G, self.C, self.yy = np.stack(G), np.stack(C), np.stack(yy)

    def centred(self, blocks, cols, mp, mr):
        """Gram, cross and target sums of the blocks ``blocks`` on the columns ``cols``, centred at
        the feature means ``mp`` and target means ``mr`` (a fold's training means)."""
        n = self.n[blocks].sum()
        sA, sY = self.sA[blocks].sum(axis=0)[cols], self.sY[blocks].sum(axis=0)
        G = self.G[blocks].sum(axis=0)[np.ix_(cols, cols)]
        G = G - np.outer(sA, mp) - np.outer(mp, sA) + n * np.outer(mp, mp)
        C = self.C[blocks].sum(axis=0)[cols]
        C = C - np.outer(sA, mr) - np.outer(mp, sY) + n * np.outer(mp, mr)
        yy = self.yy[blocks].sum(axis=0) - 2 * mr * sY + n * mr**2
        return G, C, yy


def _eig(G, C):
    """The Gram's eigenvalues ``w`` (ascending, rounding below 0 cut), vectors ``V`` and ``V^T C``:
    the ridge coefficients for a penalty ``lam`` are then ``V (V^T C / (w + lam))``."""
    w, V = np.linalg.eigh(G)
    return np.maximum(w, 0.0), V, V.T @ C


def _ridge_blocks(mom, blocks, cols, mp, mr):
    """Ridge regression coefficients (p, k) fitted on the blocks ``blocks``, each target column's
    penalty chosen on a log grid by two-fold cross-validation over alternate blocks of these
    training blocks themselves: consecutive samples share their noise, so a penalty judged
    sample by sample (leave-one-out, GCV) lets the black box chase the noise between blocks."""
    G, C, _ = mom.centred(blocks, cols, mp, mr)
    w, V, VtC = _eig(G, C)
    grid = max(float(w[-1]), 1e-300) * RIDGE_GRID
    cv = np.zeros((len(grid), C.shape[1]))
    for f in (0, 1):
        trb, teb = blocks[f::2], blocks[1 - f::2]
        if not len(trb) or not len(teb):
            continue
        Gt, Ct, _ = mom.centred(trb, cols, mp, mr)
        Ge, Ce, yye = mom.centred(teb, cols, mp, mr)
        wt, Vt_, VtCt = _eig(Gt, Ct)
        for i, lam in enumerate(grid):
            B = Vt_ @ (VtCt / (wt + lam)[:, None])
            # the held-out blocks' squared error from their sums: |y|^2 - 2 B.c + B^T G B
            cv[i] += yye - 2 * np.sum(B * Ce, axis=0) + np.sum(B * (Ge @ B), axis=0)
    lam = grid[np.argmin(cv, axis=0)]
    return V @ (VtC / (w[:, None] + lam[None, :]))


def black_box_noise(s, resid, m, seed: int = 0):
    """Per-channel torque noise [N m] of a record that does not repeat: the held-out RMS of a
    flexible black-box model of the nominal residual ``resid`` (N, n) [N m], fitted (ridge) on
    alternate blocks of the record and tested on the others, both ways. The model is a smooth
    function of the motion (random Fourier features of the angles' sines and cosines, rates and
    accelerations; each joint's rate, acceleration and smoothed sign of the rate; the nominal
    torque's time derivative): a structured model error (friction, inertia, a delay, a payload)
    is a function of the motion and is predicted, noise is not. The same fit on the per-joint
    terms alone (no random features, a penalty of their own) is a second bound, and the per-joint
    terms with a cosine series in each joint's angle over its range (a ripple that repeats with
    the angle: cogging, a transmission error) a third; when ``s`` carries the rigid-body regressor
    ``Y`` (N, n, 10 n), the per-joint terms with each channel's own row of it (an inertial error is
    linear in it) a fourth; each channel takes the smallest. An upper bound of the noise (what the
    models cannot represent stays in it).
    Returns ``(sigma, dof, info)``; ``info["base_only"]``: the channels whose bound came from the
    per-joint terms, ``info["angle_series"]``: those whose bound came from the angle series,
    ``info["rigid_body"]``: those whose bound came from the regressor rows, ``info["history"]``:
    those whose bound came from the per-joint terms with the joint's motion through plays
    (:func:`_history_terms`: a residual that depends on the motion's history)."""
    N, n = resid.shape
    q, qd, qdd = (np.asarray(v, float) for v in (s.q, s.qd, s.qdd))
    h = float(np.mean(np.diff(s.t)))

    def z(v):
        sd = v.std(axis=0)
        return (v - v.mean(axis=0)) / np.where(sd > 0, sd, 1.0)

    v0 = 0.05 * np.maximum(qd.std(axis=0), 1e-12)
    base = [np.ones((N, 1)), z(qd), z(qdd), np.tanh(qd / v0), np.sin(q), np.cos(q),
            z(np.gradient(np.asarray(s.F0, float), h, axis=0))]
    Z = np.concatenate([np.sin(q), np.cos(q), z(qd), z(qdd)], axis=1)
    rng = np.random.default_rng(seed)
    M = int(max(0, min(BLACK_BOX_FEATURES, N // 8 - sum(b.shape[1] for b in base))))
    W = rng.standard_normal((Z.shape[1], M)) / np.sqrt(Z.shape[1])
    Phi = np.concatenate(base + [np.cos(Z @ W + rng.uniform(0, 2 * np.pi, M))], axis=1)
    sd = Phi.std(axis=0)
    Phi = np.where(sd > 0, (Phi - Phi.mean(axis=0)) / np.where(sd > 0, sd, 1.0), 1.0)
    ids = np.arange(N) * BLACK_BOX_BLOCKS // N
    nb = sum(b.shape[1] for b in base)
    # the random features are smooth in the angles (a few radians per cycle): a ripple of many
    # cycles per turn, a function of one angle, is beyond them (a 3-joint arm's cogging at 27
    # cycles a turn stayed in the floor, 4.1 % against 0.7 % of noise, and a spring was
    # `explained` inside it); a series in each angle alone reaches it with few terms
    span = np.ptp(q, axis=0)
    mv = np.flatnonzero(span > 1e-9)
    u = (q[:, mv] - q[:, mv].min(axis=0)) / np.where(span[mv] > 0, span[mv], 1.0)
    Ks = [K for K in BLACK_BOX_HARMONICS if len(mv) and nb + K * len(mv) <= N // 8]

    def series(K):
        return z(np.cos(np.pi * u[:, :, None] * np.arange(1, K + 1)).reshape(N, -1))

    nbk = BLACK_BOX_BLOCKS
    # one feature matrix holds every model's columns (the angle series nest: 8 in 16 in 32)
    Kmax = max(Ks, default=0)
    A = np.concatenate([Phi] + ([series(Kmax)] if Kmax else []), axis=1)
    nrff = Phi.shape[1]
    mom = _Moments(A, resid, ids, nbk)
    base_cols = np.arange(nb)
    models = [np.arange(nrff), base_cols]
    for K in Ks:
        # the series' columns are joint-major, K per moving joint: the first K of each
        sel = (np.arange(len(mv))[:, None] * Kmax + np.arange(K)[None, :]).ravel()
        models.append(np.concatenate([base_cols, nrff + sel]))

    def held_out(cols, mom=mom, A=A, target=resid):
        err = np.zeros_like(target)
        P = A[:, cols]
        for f in (0, 1):
            trb = np.arange(f, nbk, 2)
            tr, te = ids % 2 == f, ids % 2 != f
            # the intercept is not penalised: a constant share of the residual (a sensor offset, a
            # weight the sensor does not report) is a model error, never noise, however large it is
            mr, mp = target[tr].mean(axis=0), P[tr].mean(axis=0)
            B = _ridge_blocks(mom, trb, cols, mp, mr)
            err[te] = target[te] - mr - (P[te] - mp) @ B
        return err

    def per_channel_errors(extra):
        """Held-out errors of the per-joint terms with ``extra(j)`` (N, k) for each channel ``j`` in
        the gap; a channel whose record is too short for them keeps its residual (no bound)."""
        err = resid - resid.mean(axis=0)
        for j in np.flatnonzero(np.asarray(m, bool)):
            Xj = extra(j)
            if nb + Xj.shape[1] > N // 8:
                continue
            Aj = np.concatenate([Phi[:, :nb], Xj], axis=1)
            sd = Aj.std(axis=0)
            Aj = np.where(sd > 0, (Aj - Aj.mean(axis=0)) / np.where(sd > 0, sd, 1.0), 0.0)
            cols = np.flatnonzero(sd > 0)
            mj = _Moments(Aj, resid[:, j:j + 1], ids, nbk)
            err[:, j] = held_out(cols, mj, Aj, resid[:, j:j + 1])[:, 0]
        return err

    # the random features' penalty shrinks the base terms with them: a light joint's viscous
    # friction (a Panda's joint 7, 12 % of its torque) was left 40 % unpredicted, its floor 14 x
    # the noise. Every model's held-out error bounds the noise from above: each channel takes the
    # tightest
    errs = [held_out(c) for c in models]
    rigid_at = -1  # where the per-channel models' errors sit in errs (-1: no such model)
    Y = getattr(s, "Y", None)
    if Y is not None and nb + Y.shape[2] <= N // 8:
        # the per-joint terms with the channel's own rigid-body regressor row: an inertial error
        # (CAD masses, a payload) is linear in it, but through sums of angles and products of
        # rates the smooth features above reach only roughly (a UR5 shoulder's bound stayed at
        # 4 x its noise with a 7 % mass error)
        # through the set's parallel filter: the copy the inertial refit made and keeps with the set
        Yf = _filtered(s, "Y") if hasattr(s, "cache") else Y
        rigid_at = len(errs)
        errs.append(per_channel_errors(lambda j: Yf[:, j, :]))
    # the per-joint terms with the joint's motion through plays of a few widths (the displacement a
    # play leaves and its rates): a residual that depends on the motion's history (gear play, a
    # hysteresis: which side of a gap the teeth are on) is no function of the present motion, and
    # the smooth features kept it as noise (a 3-joint arm's play: floor 32.3 % against a 31.8 % gap)
    history_at = len(errs)
    errs.append(per_channel_errors(lambda j: _history_terms(s, j)))
    if hasattr(s, "cache"):
        # kept for the channels of this call only: 70 MB on a 5 kHz 6-joint record, read by nothing
        # else (a second floor of the same set makes them again, the same)
        s.cache.pop("history_terms", None)
    rms = np.stack([np.sqrt(np.mean(e**2, axis=0)) for e in errs])
    for k in (rigid_at, history_at):  # channels left out of the gap hold no per-channel model's error
        if k >= 0:
            rms[k, ~np.asarray(m, bool)] = np.inf
    pick = np.argmin(rms, axis=0)
    err = np.stack([errs[pick[j]][:, j] for j in range(n)], axis=1)
    sig = rms[pick, np.arange(n)]
    dof = np.array([effective_samples(err[:, j]) if m[j] else 1.0 for j in range(n)])
    mk = np.asarray(m, bool)
    # a channel no model predicted any of: its bound is its own residual, noise or an error that is
    # no function of the motion (the floor cannot tell which)
    own = np.sqrt(np.mean((resid - resid.mean(axis=0)) ** 2, axis=0))
    unpredicted = [int(j) for j in np.flatnonzero(mk & (sig >= UNPREDICTED * own) & (own > 0))]
    return sig, dof, dict(features=int(Phi.shape[1]), base_features=int(nb), blocks=BLACK_BOX_BLOCKS,
                          unpredicted=unpredicted,
                          harmonics=Ks, base_only=[int(j) for j in np.flatnonzero((pick == 1) & mk)],
                          angle_series=[int(j) for j in np.flatnonzero((pick >= 2) & (pick < len(models)) & mk)],
                          rigid_body=[int(j) for j in np.flatnonzero((pick == rigid_at) & mk)],
                          history=[int(j) for j in np.flatnonzero((pick == history_at) & mk)])


# [rad] half-widths of the plays the history terms pass each angle through: fine enough that one
# lies near any gear's (the engagement's timing, which the torque shows, moves with the width)
HISTORY_WIDTHS = tuple(np.geomspace(0.001, 0.03, 12))


def _history_terms(s, j: int) -> np.ndarray:
    """Columns of the motion's history for channel ``j``, through the set's parallel filter: for
    each width ``b`` of :data:`HISTORY_WIDTHS`, the displacement a play of half-width ``b`` leaves
    at joint ``j`` (``play(q_j, b) - q_j``, the side of the gap it sits on) and its first and
    second rates; and, for every moving joint ``k``, the change of joint ``j``'s rigid torque when
    link ``k`` lags by its own play's displacement (the nominal model's inertia and gravity weigh
    it with the posture; a play at one joint loads the others through the inertia matrix)."""
    from ..torque._terms import link_lag_column, play

    def make():
        q = np.asarray(s.q, float)
        h = float(np.mean(np.diff(s.t)))
        moving = [k for k in range(q.shape[1]) if np.ptp(q[:, k]) > 1e-9]
        own, lagged = {}, []
        for k in moving:
            for b in HISTORY_WIDTHS:
                d = play(q[:, k], b) - q[:, k]
                dd = np.gradient(d, h)
                own.setdefault(k, []).extend([d, dd, np.gradient(dd, h)])
                if getattr(s, "robot", None) is not None:
                    lagged.append(link_lag_column(s, k, d))  # (N, n)
        lp = s.lp if hasattr(s, "lp") else (lambda X: X)
        L_ = lp(np.stack(lagged, axis=2).reshape(q.shape[0], -1)).reshape(q.shape + (len(lagged),)) if lagged \
            else np.zeros(q.shape + (0,))
        return {k: lp(np.stack(v, axis=1)) for k, v in own.items()}, L_

    own, L_ = _product(s, "history_terms", make) if hasattr(s, "cache") else make()
    return np.concatenate([own.get(j, np.zeros((L_.shape[0], 0))), L_[:, j, :]], axis=1)


def frf_floor(a: dict, err) -> tuple[float, str]:
    """NRMSE [%] that noise alone leaves on an FRF set with arrays ``a`` and model error ``err``
    (F, 3, 3), and its source: ``H_repeats`` when recorded, else the residual's second difference
    along frequency (see :func:`noise_floor`)."""
    ok = L.frf_entries(a["H"])
    if "H_repeats" in a:
        rep = a["H_repeats"]
        # per-entry noise variance of one record (unbiased), summed over frequency and set
        # against the FRF's energy: the measure of the gap itself
        var = np.sum(np.abs(rep - rep.mean(axis=0)) ** 2, axis=0) / max(rep.shape[0] - 1, 1)
        var = var / repeats_factor(rep, a["H"]) ** 2
        return float(np.sqrt(np.sum(var[:, ok]) / np.sum(np.abs(a["H"][:, ok]) ** 2)) * 100), "H_repeats"
    e = err[:, ok] / L.frf_scale(a["H"])[ok]
    d2 = e[2:] - 2 * e[1:-1] + e[:-2]
    sig = np.sqrt(robust_sigma(d2.real) ** 2 + robust_sigma(d2.imag) ** 2) / np.sqrt(6)
    return float(sig * 100), "residual second difference"


def fits_to_noise(lm, x, sets, case, factor: float = 3.0, margin: float = 1.0) -> bool:
    """Whether the linear model ``lm`` at log parameters ``x`` fits every FRF/modal set in ``sets``
    to within ``factor`` times its noise floor plus ``margin`` [%] (NRMSE as the gap is measured)."""
    for d in sets:
        a = d.arrays
        if d.kind == "frf":
            Hm = lm.frf(x, a["q0"], a["freq"])
            err = np.where(np.isfinite(Hm), Hm, 0.0) - a["H"]
            ok = L.frf_entries(a["H"])
            gap = np.sqrt(np.sum(np.abs(err[:, ok]) ** 2) / np.sum(np.abs(a["H"][:, ok]) ** 2)) * 100
            floor = frf_floor(a, err)[0]
        else:
            ef, ez, *_ = L.modal_errors(lm, x, a)
            gap = np.sqrt(np.mean(ef**2) + np.mean((L.DAMPING_WEIGHT * ez) ** 2)) * 100
            floor = modal_floor(case, a.get("zeta"))[0]
        if not np.isfinite(gap) or gap > factor * floor + margin:
            return False
    return True


MODAL_FREQUENCY_PCT = 1.0  # default scatter of identified natural frequencies [%]
MODAL_DAMPING_PCT = 15.0  # default scatter of identified damping ratios [%]: EMA rarely does better


def modal_floor(case: Case, zeta=None) -> tuple[float, str]:
    """NRMSE [%] that the scatter of identified modes leaves on a modal table, measured as the gap
    is (:func:`._frequency_model.modal_errors`: the frequency error plus ``DAMPING_WEIGHT`` x the relative
    damping error): ``sqrt(f^2 + (DAMPING_WEIGHT d)^2)`` with ``f`` = ``noise.modal_frequency_pct``
    and ``d`` = ``noise.modal_damping_pct`` of the case (defaults 1 % and 15 %); ``d`` only when the
    table's damping ratios ``zeta`` hold a measured value."""
    f = float(case.noise.get("modal_frequency_pct", MODAL_FREQUENCY_PCT))
    d = float(case.noise.get("modal_damping_pct", MODAL_DAMPING_PCT))
    if zeta is not None and not np.any(np.isfinite(np.asarray(zeta, float))):
        d = 0.0
    src = ", ".join(f"noise.{k}" if k in case.noise else f"default {v:g} % ({k})"
                    for k, v in (("modal_frequency_pct", MODAL_FREQUENCY_PCT), ("modal_damping_pct", MODAL_DAMPING_PCT)))
    return float(np.hypot(f, L.DAMPING_WEIGHT * d)), src
