"""Processing of a torque log that gave angles only (or angles and velocities): the motion's band
read off the angle spectrum, a zero-phase low-pass at a cutoff chosen from it, differentiation of
the smooth signal, the same filter on the measured torques (parallel filtering), and the noise the
filtered residual keeps, predicted from the raw torque's spectrum and from the angle noise redrawn
through the processing. The model's columns go through the same filter (the caller's part).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .._errors import DataError
from ._condition import CUTOFF_FACTOR, CUTOFF_LIMIT, choose_cutoff, resample_uniform
from ._signal import (angle_noise, band_noise_psd, filtered_derivatives, lowpass_power_gain, motion_band, shift,
                      velocity_lag, zero_phase_lowpass)

VELOCITY_LAG_MIN = 0.1  # x the sample step: logged velocities lagging the angles by more are moved back
NOISE_DRAWS = 4  # angle-noise redraws propagated through the processing and the model (noise floor)
NOISE_BAND = (1.5, 4.0)  # x the motion band: where the raw torque's noise level is read
EDGE_PERIODS = 2.0  # periods of the cutoff trimmed off each end of a filtered record (transients)


@dataclasses.dataclass
class AngleLog:
    """One angle-only (or velocity-only) log, resampled, filtered and differentiated
    (:func:`process_angle_log`). ``rows`` holds the resampled raw rows (its ``qd`` moved back by
    the velocities' lag); ``q``, ``qd``, ``qdd``, ``tau`` the filtered signals at the stamps ``t``
    (step ``h``), all untrimmed."""

    t: np.ndarray
    h: float
    rows: dict
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    cutoff: float
    cutoff_info: dict
    sampling: dict
    angle_noise: np.ndarray  # (n,) [rad] the band is read against
    draw_noise: np.ndarray  # (n,) [rad] redrawn through the processing (read off the motion)
    velocity_noise: np.ndarray | None  # (n,) [rad/s] redrawn on logged velocities, None for angles only
    motion_band: float  # [Hz] against the angle noise, as reported
    lag: float  # [s] of the logged velocities behind the angles' rate (0 for angles only)
    torque_variance: np.ndarray  # (n,) [N^2 m^2] of the raw torque's noise through the filter

    def derive(self, qr, qdr=None):
        """Filtered angles, rates and accelerations of raw angles ``qr`` (and velocities ``qdr``):
        angles differentiated twice, or velocities filtered and differentiated once."""
        h, fc = self.h, self.cutoff
        if qdr is None:
            return filtered_derivatives(qr, h, fc)
        qf, qdf = zero_phase_lowpass(qr, h, fc), zero_phase_lowpass(qdr, h, fc)
        return qf, qdf, np.gradient(qdf, h, axis=0)


def log_cutoff(q_raw, h: float, f_m: float, qd, cutoff_hz, decimate: int, where: str, resampled: bool = False):
    """``(cutoff [Hz], info, band [Hz] the cutoff stands for)`` of a log with angles ``q_raw`` at
    step ``h`` and motion band ``f_m``: :func:`jflex.data.choose_cutoff` for ``"auto"`` (or None),
    else the given cutoff, refused unless below 0.9 x the Nyquist frequency after ``decimate``."""
    nyq = 0.5 / (h * decimate)
    if cutoff_hz in (None, "auto"):
        fc, cut = choose_cutoff(q_raw, h, qd=qd, factor=CUTOFF_FACTOR, decimate=decimate, limit=CUTOFF_LIMIT,
                                resampled=resampled)
        f_b = fc / CUTOFF_FACTOR  # the band the cutoff stands for (the motion band, or the fallback's)
        return fc, cut, f_b
    fc, cut = float(cutoff_hz), {"method": "given (options.filter_cutoff_hz)", "nyquist_hz": nyq}
    # the band the given cutoff stands for: the motion band when it lies below the cutoff, else
    # (a band read off a spectrum that never meets the angle noise) the cutoff's own
    f_b = f_m if 0 < f_m < fc else fc / CUTOFF_FACTOR
    if not 0 < fc < 0.9 * nyq:
        raise DataError(f"{where}: the low-pass cutoff {fc:.3g} Hz must lie below 0.9 x the Nyquist frequency "
                        f"{nyq:.3g} Hz of this record{' after decimation' if decimate > 1 else ''} "
                        "(options.filter_cutoff_hz, options.decimate; filter_cutoff_hz: auto chooses a cutoff per "
                        "record)")
    return fc, cut, f_b


def filtered_torque_variance(tau_raw, h: float, fc: float, f_b: float):
    """(n,) noise variance of the torque ``tau_raw`` low-passed at ``fc``: the raw torque's PSD
    above the band ``f_b`` (measured), extrapolated flat below ``NOISE_BAND[0]`` x the band, times
    the filter's power gain."""
    level, f, P = band_noise_psd(tau_raw, h, NOISE_BAND[0] * f_b, NOISE_BAND[1] * f_b)
    g = lowpass_power_gain(f, h, fc)
    df = f[1] - f[0]
    hi = f > NOISE_BAND[0] * f_b
    return (P[hi] * g[hi, None]).sum(axis=0) * df + level * (g[~hi].sum() * df)


def process_angle_log(t, rows: dict, where: str, *, cutoff_hz="auto", decimate: int = 1,
                      velocity_only: bool = False, resampled: bool = False) -> AngleLog:
    """Resample ``rows`` (``q``, ``tau``, ``q_extra``, and ``qd`` when ``velocity_only``, ``tau_valid``
    when some samples are masked) at stamps ``t`` onto a uniform grid, read the angle noise and the
    motion band, choose the cutoff (:func:`log_cutoff`), move logged velocities that lag the angles
    back, filter and differentiate, filter the torques and predict their noise. ``resampled``: the
    rows were resampled from jittered stamps already (:func:`jflex.data.condition_torque`)."""
    t, rows, sampling = resample_uniform(t, rows, where)
    resampled = resampled or sampling["resampled"]
    q_raw, tau_raw = rows["q"], rows["tau"]
    h = float(np.mean(np.diff(t)))
    sig_q = angle_noise(q_raw)
    # the angle noise redrawn through the processing (the floor's processing term): read off the
    # motion (a fast smooth motion's second difference is no noise)
    sig_draw = angle_noise(q_raw, motion_free=True)
    f_m = motion_band(q_raw, h, sig_q, resampled=resampled)
    fc, cut, f_b = log_cutoff(q_raw, h, f_m, rows.get("qd"), cutoff_hz, decimate, where, resampled)
    sig_qd = None
    if velocity_only:
        # the velocities' noise where the filter lets it through: a differenced encoder's is blue
        # (its total, the grid step of the differences, is mostly far above the cutoff), and a
        # white redraw at its total level made a periodic floor 3.6 x the gap of a null log
        lvl = band_noise_psd(rows["qd"], h, NOISE_BAND[0] * f_b, NOISE_BAND[1] * f_b)[0]
        sig_qd = np.minimum(angle_noise(rows["qd"]), np.sqrt(lvl / (2.0 * h)))
    lag = velocity_lag(q_raw, rows["qd"], h, fc) if velocity_only else 0.0
    if abs(lag) > VELOCITY_LAG_MIN * h:
        # velocities logged late (a backward difference of the encoder: half a sample) against the
        # angles they come with: the model would see a velocity and an acceleration that lag the
        # posture, a repeating error no floor holds (1 % of the torque on a planar arm)
        rows["qd"] = shift(rows["qd"], t, -lag)
    log = AngleLog(t, h, rows, None, None, None, None, fc, cut, sampling, sig_q, sig_draw, sig_qd, f_m, lag, None)
    log.q, log.qd, log.qdd = log.derive(q_raw, rows.get("qd"))
    log.tau = zero_phase_lowpass(tau_raw, h, fc)
    log.torque_variance = filtered_torque_variance(tau_raw, h, fc, f_b)
    return log


def propagated_noise(log: AngleLog, deviation, draws: int = NOISE_DRAWS):
    """(n,) variance of ``deviation(q, qd, qdd)`` (the model's torque change) over ``draws``
    redraws of the angle noise (and the velocity noise) through the log's processing."""
    q_raw, rows, sig_draw, sig_qd = log.rows["q"], log.rows, log.draw_noise, log.velocity_noise
    rng = np.random.default_rng(0)
    dev = []
    for _ in range(draws):
        qk, qdk, qddk = log.derive(q_raw + sig_draw * rng.standard_normal(q_raw.shape),
                                   None if sig_qd is None else rows["qd"] + sig_qd * rng.standard_normal(q_raw.shape))
        dev.append(deviation(qk, qdk, qddk))
    return np.mean([d.var(axis=0) for d in dev], axis=0)


def trimmed(log: AngleLog, where: str, decimate: int = 1):
    """``(rows kept, weights or None, trimmed samples per end)``: the filter's start and end
    transients (zero-phase: both ends, ``EDGE_PERIODS`` periods of the cutoff) cut off the log,
    every ``decimate``-th sample kept; masked torque samples (``tau_valid``) widened by the
    filter's reach, one period of the cutoff each way."""
    t, h, fc, k = log.t, log.h, log.cutoff, int(decimate)
    edge = int(np.ceil(EDGE_PERIODS / fc / h))
    if t.size - 2 * edge < 20 * k:
        raise DataError(f"{where}: field 't': the record ({t[-1] - t[0]:.3g} s) is too short for its low-pass at "
                        f"{fc:.3g} Hz, whose transients take {edge * h:.3g} s at each end")
    sl = slice(edge, t.size - edge, k)
    weight = None
    if "tau_valid" in log.rows:
        from scipy.ndimage import minimum_filter1d

        reach = int(np.ceil(1.0 / (fc * h)))
        weight = minimum_filter1d((log.rows["tau_valid"] >= 1.0 - 1e-9).astype(float), 2 * reach + 1, axis=0,
                                  mode="nearest")[sl]
    return sl, weight, edge
