"""Signal processing of measured joint positions (the thesis "Posture Dependent Dynamics in Robotic Machining" section 3.2.5): FFT low-pass
filtering and spectral differentiation of periodic records."""

from __future__ import annotations

import numpy as np

from .._errors import DataError
from ._validate import check_finite


def robust_sigma(x, axis=None):
    """The standard deviation of Gaussian noise from the median absolute deviation,
    ``1.4826 MAD`` (Rousseeuw and Croux, "Alternatives to the median absolute deviation"): of every
    value of ``x``, or per slice along ``axis``."""
    if axis is None:
        x = np.asarray(x).ravel()
        return 1.4826 * np.median(np.abs(x - np.median(x)))
    x = np.asarray(x)
    return 1.4826 * np.median(np.abs(x - np.median(x, axis=axis, keepdims=True)), axis=axis)


def _spectrum(x, dt):
    x = np.asarray(x, dtype=float)
    n = x.shape[0]
    return np.fft.rfft(x, axis=0), np.fft.rfftfreq(n, dt), n


def fft_lowpass(x, dt: float, cutoff: float):
    """Zero every Fourier coefficient above ``cutoff`` (an ideal, zero-phase low-pass).

    **Arguments:** ``x`` (N, ...) samples along axis 0, evenly spaced by ``dt`` [s];
    ``cutoff`` [Hz].

    **Returns:** filtered ``x`` (N, ...). Exact for records holding whole periods of a periodic
    signal (an excitation trajectory); otherwise leakage appears at the record ends.
    """
    X, f, n = _spectrum(check_finite(x, "x"), dt)
    X[f > cutoff] = 0.0
    return np.fft.irfft(X, n=n, axis=0)


def spectral_derivatives(q, dt: float, cutoff: float | None = None):
    """Filtered positions, velocities and accelerations by differentiation in the frequency domain.

    ``qd = F^-1[i w Q]``, ``qdd = F^-1[-w^2 Q]`` after zeroing components above ``cutoff``.

    **Arguments:** ``q`` (N, n) positions sampled every ``dt`` [s] over whole periods;
    ``cutoff`` [Hz] (default: Nyquist, i.e. no filtering).

    **Returns:** ``(q_f, qd, qdd)``, each (N, n).
    """
    q = check_finite(q, "q")
    if q.shape[0] < 4:
        raise DataError(f"spectral_derivatives: need at least 4 samples, got {q.shape[0]}")
    X, f, n = _spectrum(q, dt)
    if cutoff is not None:
        X[f > cutoff] = 0.0
    if n % 2 == 0:
        # The Nyquist bin has no sign information: its derivative is not defined, drop it.
        X[-1] = 0.0
    w = (2 * np.pi * f).reshape((-1,) + (1,) * (q.ndim - 1))
    q_f = np.fft.irfft(X, n=n, axis=0)
    qd = np.fft.irfft(1j * w * X, n=n, axis=0)
    qdd = np.fft.irfft(-(w**2) * X, n=n, axis=0)
    return q_f, qd, qdd


# --- records that are not periodic: measured logs -------------------------------------------------
BUTTER_ORDER = 4  # zero-phase Butterworth: order 4 each way (8 in all), flat pass band, no lag
MOTION_SNR = 100.0  # the motion's band ends where its angle spectrum falls to 100 x the angle noise


REPEATS = 0.05  # a column whose reading stays the same over 5 % of its steps or more while it moves
REPEAT_RUN = 50  # (in holds of at most 50 steps: a longer one is a rest) is quantised coarsely
POWER_SHARE = 0.999  # ... and its motion band is held within POWER_SPAN x where this share of its power lies
POWER_SPAN = 2.0
POWER_RESOLUTION = 0.5  # [Hz] frequency step of the spectrum that cap is read off (a 1024-sample Welch
# segment steps 4.9 Hz at 5 kHz: a 2-3 Hz motion read 14.6 Hz there)


def _repeats(q) -> np.ndarray:
    """(n,) bool: the columns of ``q`` (N, n) whose reading stays the same over ``REPEATS`` of the
    steps, counting holds of at most ``REPEAT_RUN`` steps (an encoder grid coarser than a step of
    the motion; a robot at rest holds its reading far longer)."""
    q = np.asarray(q, dtype=float)
    out = np.zeros(q.shape[1], bool)
    if q.shape[0] < 2:
        return out
    for j, z in enumerate((np.diff(q, axis=0) == 0).T):
        run = np.concatenate([[0], np.cumsum(z[1:] != z[:-1])])
        length = np.bincount(run)[run]
        out[j] = np.mean(z & (length <= REPEAT_RUN)) >= REPEATS
    return out


def angle_noise(q, *, motion_free: bool = False):
    """Noise std [rad] per column of sampled angles ``q`` (N, n): the larger of the white-noise
    estimate from the robust spread of the second difference, ``MAD(d2 q) / sqrt(6)``, and the
    quantisation noise ``step / sqrt(12)`` of an encoder whose readings sit on a grid (the second
    difference of a slowly moving quantised angle is mostly zero, so its MAD alone reads ~0, or one
    count where about half of it is not: the rounding alone, then, whose noise is ``step / sqrt(12)``). The
    step is the smallest nonzero increment when every increment is (near) a whole number of it, or
    when the readings repeat (``REPEATS``: a grid the log's rounding or resampling has blurred).
    ``motion_free``: off a grid, the smaller of that and the fourth difference's estimate
    (``MAD(d4 q) / sqrt(70)``), which a smooth motion sampled fast barely enters."""
    q = np.asarray(q, dtype=float)
    d2 = q[2:] - 2 * q[1:-1] + q[:-2]
    mad = robust_sigma(d2, axis=0) / np.sqrt(6)
    if motion_free and len(q) > 8:
        # the second difference of a fast smooth motion holds the motion itself (qdd h^2: 2-3e-5 rad
        # at 1 kHz, an encoder's step); the fourth difference's is h^2 smaller, white noise's the
        # same in its own units (70 sigma^2): the smaller of the two is the noise
        d4 = d2[2:] - 2 * d2[1:-1] + d2[:-2]
        mad = np.minimum(mad, robust_sigma(d4, axis=0) / np.sqrt(70))
    out = np.empty(q.shape[1])
    rep = _repeats(q)
    for j in range(q.shape[1]):
        dq = np.abs(np.diff(q[:, j]))
        dq = dq[dq > 1e-15]
        step = 0.0
        if dq.size:
            s0 = float(np.min(dq))
            # a grid: every increment is (near) a whole number of the smallest one, the step
            # refined over all of them (a log that rounds its readings blurs the smallest one)
            s1 = s0
            for reach in (10.0, np.inf):  # the small multiples first: a wrong count there is unlikely
                d = dq[dq < reach * s1]
                k = np.round(d / s1)
                s1 = float(d @ k / (k @ k))
            k = np.round(dq / s1)
            if s0 > 0 and (rep[j] or np.all(np.abs(dq / s0 - k) < 0.02) or np.all(np.abs(dq - k * s1) < 0.1 * s1)):
                step = s0
        # on a grid the second difference takes whole counts, about half of them nonzero: its MAD
        # reads one count (0.6 x the step, twice the rounding's own step/sqrt(12)) though no noise
        # beyond the rounding is there; only a spread beyond one count is noise of its own
        one_count = 1.4826 * step / np.sqrt(6.0)
        out[j] = step / np.sqrt(12.0) if step > 0 and mad[j] <= one_count * (1 + 1e-9) else max(float(mad[j]), step / np.sqrt(12.0))
    return out


def held_by_power(q, resampled: bool = False) -> bool:
    """Whether :func:`motion_band` holds the band of angles ``q`` by their power (readings that
    repeat, or angles ``resampled`` from jittered stamps)."""
    return bool(resampled or _repeats(q).any())


def power_segment(n: int, dt: float, resolution_hz: float | None = None) -> int:
    """Samples per Welch segment of :func:`power_band` on ``n`` samples at step ``dt``."""
    nper = 1024 if resolution_hz is None else max(1024, int(np.ceil(1.0 / (dt * resolution_hz))))
    return min(n, nper)


def power_band(q, dt: float, share: float = POWER_SHARE, *, resolution_hz: float | None = None) -> float:
    """The highest, over the columns of ``q`` (N, n), of the frequency [Hz] below which ``share`` of
    the detrended column's power lies (Welch: segments of 1024 samples, or, with
    ``resolution_hz``, long enough to step the frequency by at most that, as far as the record
    allows)."""
    from scipy.signal import detrend, welch

    nper = power_segment(len(q), dt, resolution_hz)
    f, P = welch(detrend(np.asarray(q, float), axis=0), fs=1.0 / dt, nperseg=nper, axis=0)
    edges = [float(f[min(int(np.searchsorted(c, share * c[-1])), f.size - 1)]) for c in np.cumsum(P, axis=0).T
             if c[-1] > 0]
    return max(edges, default=0.0)


def motion_band(q, dt: float, noise=None, *, spectrum: str = "second_difference", resampled: bool = False) -> float:
    """Highest frequency [Hz] where some column's angle spectrum (Welch) stands ``MOTION_SNR``
    above the white angle noise ``noise`` (std per column, default :func:`angle_noise`).

    ``spectrum="second_difference"`` (the torque logs' band, for their Butterworth filter) reads it
    off the spectrum of the angles' second difference, held as below on quantised angles;
    ``"angles"`` (the response sets' band, for their Savitzky-Golay window) off the spectrum of the
    mean-free angles themselves (:func:`_band_on_angles`).

    On angles whose readings repeat (a coarse or blurred encoder grid, :data:`REPEATS`) the noise
    estimate is no better than the grid's: a resampled or rounded log reads a fraction of it, and
    the band ran to 20-45 x the motion's. There the band is held within ``POWER_SPAN`` x the
    frequency below which ``POWER_SHARE`` of the angles' power lies (:func:`power_band`, read in
    steps of ``POWER_RESOLUTION``). So is the band of angles ``resampled`` from jittered stamps
    onto a uniform grid: interpolated between counts and between stamps that were off, they no
    longer repeat, and their error follows the motion (a closed-loop null log read 31-38 Hz for a
    motion whose power ends below 6 Hz, and its cutoff passed the encoder's counts into the
    accelerations)."""
    from scipy.signal import welch

    q = np.asarray(q, dtype=float)
    fs = 1.0 / dt
    if spectrum == "angles":
        return _band_on_angles(q, angle_noise(q) if noise is None else np.asarray(noise, float), fs)
    if spectrum != "second_difference":
        raise ValueError(f"motion_band: spectrum is 'second_difference' or 'angles', got {spectrum!r}")
    sig = angle_noise(q) if noise is None else np.broadcast_to(np.asarray(noise, float), (q.shape[1],))
    # a floor relative to the motion keeps noise-free (synthetic or pre-filtered) angles finite
    sig = np.maximum(sig, 1e-9 * np.maximum(q.std(axis=0), 1e-12))
    # on the second difference: it whitens the motion's steep spectrum, so the window's leakage
    # from the strong low-frequency lines no longer reads as motion far above them
    d2 = q[2:] - 2 * q[1:-1] + q[:-2]
    f, P = welch(d2, fs=fs, nperseg=min(len(d2), 1024), window="blackmanharris", axis=0)
    gain = (2.0 - 2.0 * np.cos(2 * np.pi * f * dt)) ** 2  # |d2|^2 on white noise
    level = 2.0 * sig[None, :] ** 2 / fs * np.maximum(gain[:, None], 1e-300)
    above = (P > MOTION_SNR * level).any(axis=1)
    above[0] = False
    band = float(f[np.flatnonzero(above)[-1]]) if above.any() else float(f[1])
    if held_by_power(q, resampled):
        edge = power_band(q, dt, resolution_hz=POWER_RESOLUTION)
        if edge > 0:
            band = min(band, max(POWER_SPAN * edge, float(f[1])))
    return band


def _band_on_angles(q_raw, sig, fs):
    """Highest frequency [Hz] where some joint's angle spectrum (Welch) stands ``MOTION_SNR``
    above the white angle noise ``sig`` [rad].

    Not the second difference's band, on purpose: that one (held within 2 x the 99.9 % power band
    on quantised angles) serves the Butterworth filter of torque logs. On the response sets'
    trajectories (harmonics up to 0.5 Hz) it gave bands of about 1 Hz where this one gives 1.4-5 Hz,
    so a Savitzky-Golay window 1.4-5 x as long; with it the gap a planted rotor inertia leaves once
    fitted was 1.9 x the propagated floor (0.72 against 0.38 %) and a null case with 1 mrad angle
    noise read as significant (the smoothing's own error on the motion, it seems, which a floor
    propagated from noise lacks)."""
    from scipy.signal import welch

    nper = min(len(q_raw), 1024)
    f, P = welch(q_raw - q_raw.mean(axis=0), fs=fs, nperseg=nper, axis=0)
    level = 2.0 * np.maximum(sig, 1e-15) ** 2 / fs  # one-sided PSD of white noise of std sig
    above = (P > MOTION_SNR * level[None, :]).any(axis=1)
    return float(f[np.flatnonzero(above)[-1]]) if above.any() else float(f[1])


def zero_phase_lowpass(x, dt: float, cutoff: float):
    """Zero-phase Butterworth low-pass (order ``BUTTER_ORDER``, run forwards and backwards) along
    axis 0 of ``x`` (N, ...), ``cutoff`` [Hz] (its -6 dB point; the pass band is flat, so a model
    linear in its parameters filtered in parallel with the data keeps its parameters)."""
    from scipy.signal import butter, sosfiltfilt

    x = np.asarray(x, dtype=float)
    nyq = 0.5 / dt
    if not 0 < cutoff < nyq:
        raise DataError(f"zero_phase_lowpass: cutoff must lie in (0, {nyq:g}) Hz (Nyquist), got {cutoff}")
    sos = butter(BUTTER_ORDER, cutoff / nyq, output="sos")
    pad = min(3 * (2 * BUTTER_ORDER + 1) * 4, x.shape[0] - 1)
    return sosfiltfilt(sos, x, axis=0, padtype="odd", padlen=pad)


def lowpass_power_gain(f, dt: float, cutoff: float):
    """``|H(f)|^4`` of :func:`zero_phase_lowpass` at frequencies ``f`` [Hz]: the fraction of a noise
    power spectral density that passes it."""
    from scipy.signal import butter, sosfreqz

    sos = butter(BUTTER_ORDER, cutoff / (0.5 / dt), output="sos")
    _, h = sosfreqz(sos, worN=np.asarray(f, float), fs=1.0 / dt)
    return np.abs(h) ** 4


def filtered_derivatives(q, dt: float, cutoff: float):
    """Angles, rates and accelerations of a measured (non-periodic) log: :func:`zero_phase_lowpass`
    of ``q`` (N, n), then central differences of the smooth signal (the filter has removed what
    differentiation would amplify). **Returns** ``(q_f, qd, qdd)``, each (N, n)."""
    qf = zero_phase_lowpass(q, dt, cutoff)
    qd = np.gradient(qf, dt, axis=0)
    qdd = np.gradient(qd, dt, axis=0)
    return qf, qd, qdd


def band_noise_psd(x, dt: float, f_lo: float, f_hi: float):
    """Noise power spectral density level [x^2/Hz] per column of ``x`` (N, n): the median Welch
    PSD over the band (f_lo, f_hi) above the motion (the median ignores harmonics of a few sharp
    events). Also returns the Welch frequencies and PSD ``(level (n,), f, P)``."""
    from scipy.signal import welch

    x = np.asarray(x, dtype=float)
    f, P = welch(x - x.mean(axis=0), fs=1.0 / dt, nperseg=min(len(x), 1024), axis=0)
    m = (f > f_lo) & (f < f_hi)
    if m.sum() < 3:
        m = f > f_lo
    if not m.any():
        return np.zeros(x.shape[1]), f, P
    return np.median(P[m], axis=0), f, P



def velocity_lag(q, qd, dt: float, cutoff: float) -> float:
    """The lag [s] of logged velocities ``qd`` (N, n) behind the rate of the logged angles ``q``,
    both low-passed at ``cutoff`` [Hz]: the least-squares ``tau`` of ``qd(t) = dq/dt(t - tau)``
    to first order, ``qd - dq/dt = -tau d2q/dt2``, pooled over the joints. A drive that logs the
    backward difference of its encoder reads its velocity half a sample late (``dt / 2``), an
    observer or a filter more; the model then sees a motion whose velocity lags its angle."""
    q, qd = np.asarray(q, float), np.asarray(qd, float)
    qf = zero_phase_lowpass(q, dt, cutoff)
    v = np.gradient(qf, dt, axis=0)
    a = np.gradient(v, dt, axis=0)
    vl = zero_phase_lowpass(qd, dt, cutoff)
    k = max(int(np.ceil(2.0 / (cutoff * dt))), 2)  # the filter's transients at both ends
    if len(q) <= 4 * k:
        return 0.0
    e, a = (vl - v)[k:-k], a[k:-k]
    den = float(np.sum(a * a))
    return float(-np.sum(e * a) / den) if den > 0 else 0.0


def shift(X, t, d):
    """``S_d X``: the signal delayed by ``d`` [s], of either sign (negative: advanced), by linear
    interpolation; the samples the shift leaves without data hold the record's first value (``d >
    0``) or its last (``d < 0``)."""
    if d == 0:
        return X
    flat = X.reshape(X.shape[0], -1)
    out = np.empty_like(flat)
    for k in range(flat.shape[1]):
        out[:, k] = np.interp(t - d, t, flat[:, k])
    return out.reshape(X.shape)
