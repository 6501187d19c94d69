"""The noise of a periodic record (an excitation trajectory repeated, as identification logs
are): the period of the motion, the scatter of the torque between periods, and the effective
number of independent samples of a variance estimate."""

from __future__ import annotations

import numpy as np

from ..torque._set import _filtered


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


def repeating_processing_error(s, m, sig) -> np.ndarray:
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
