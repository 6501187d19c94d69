"""Response data sets (applied torques, measured joint angles or tip positions): their fields
checked, stamps made uniform, and joint angles smoothed and differentiated into an equation-error
set whose noise is propagated through the model."""

from __future__ import annotations

import numpy as np

from .._errors import DataError
from ._condition import resample_uniform
from ._fields import numeric_field
from ._signal import motion_band, robust_sigma


TIP_CHANNELS = ("tip_x", "tip_y", "tip_z")  # [m] origin of the case's tool_frame in base axes
RESPONSE_NOISE_DRAWS = 4  # noise realisations propagated into the equation error (noise floor)
RESPONSE_CUTOFF_FACTOR = 2.0
RESPONSE_SG_ORDER = 5


def response_arrays(arrs, path, joint_names, inverse_dynamics):
    """A response data set's arrays checked (``t``, applied ``tau`` (N, n), measured ``y`` (N, k) of
    ``channels``; ``q0``, ``y_repeats`` for a simulated one): ``(arrays, ())``. A set whose channels
    name every joint of ``joint_names`` is an equation-error set (:func:`response_motion`, with the
    model's ``inverse_dynamics(q, qd, qdd)``)."""
    for k in ("t", "tau", "y", "channels"):
        if k not in arrs:
            raise DataError(f"{path}: field '{k}': missing (a response data set needs t, tau (N, n), y (N, k), channels (k,))")
    t = numeric_field(arrs["t"], path, "t", ndim=1)
    tau = numeric_field(arrs["tau"], path, "tau", ndim=2)
    y = numeric_field(arrs["y"], path, "y", ndim=2)
    ch = tuple(str(c) for c in np.asarray(arrs["channels"]).ravel())
    if tau.shape[0] != t.size or y.shape[0] != t.size:
        raise DataError(f"{path}: fields 'tau'/'y': expected {t.size} rows (as t), got {tau.shape[0]} and {y.shape[0]}")
    if len(ch) != y.shape[1]:
        raise DataError(f"{path}: field 'channels': {len(ch)} names for {y.shape[1]} columns of 'y'")
    if len(set(ch)) != len(ch):
        raise DataError(f"{path}: field 'channels': names must be unique, got {list(ch)}")
    n = len(joint_names)
    if tau.shape[1] != n:
        raise DataError(f"{path}: field 'tau': expected {n} columns (applied torques at the model joints "
                        f"{list(joint_names)}), got {tau.shape[1]}")
    known = tuple(joint_names) + TIP_CHANNELS
    bad = [c for c in ch if c not in known]
    if bad:
        raise DataError(f"{path}: field 'channels': unknown channels {bad}; a channel is a model joint "
                        f"{list(joint_names)} [rad] or one of {list(TIP_CHANNELS)} [m] (the case's tool_frame)")
    out = {"t": t, "tau": tau, "y": y, "channels": ch}
    if all(j in ch for j in joint_names):
        out.update(response_motion(t, tau, y, ch, path, joint_names, inverse_dynamics))
        return out, ()
    # output error: the model is simulated under tau from rest at q0 and its channels compared
    if t.size < 20:
        raise DataError(f"{path}: field 't': need at least 20 samples, got {t.size}")
    if np.any(np.diff(t) <= 0):
        raise DataError(f"{path}: field 't': time must be strictly increasing")
    if "q0" not in arrs:
        raise DataError(f"{path}: field 'q0': missing (a response whose channels do not name every model joint "
                        f"{list(joint_names)} is simulated from rest at q0 ({n},) [rad])")
    q0 = numeric_field(arrs["q0"], path, "q0")
    if q0.shape != (n,):
        raise DataError(f"{path}: field 'q0': expected shape ({n},) (the rest posture at t[0], model joints "
                        f"{list(joint_names)} in that order) [rad], got shape {q0.shape}")
    out["q0"] = q0
    if "y_repeats" in arrs:
        r = numeric_field(arrs["y_repeats"], path, "y_repeats", ndim=3)
        if r.shape[1:] != y.shape:
            raise DataError(f"{path}: field 'y_repeats': expected (R, {y.shape[0]}, {y.shape[1]}) (repeats of y), got {r.shape}")
        out["y_repeats"] = r
    return out, ()


def uniform_response(arrs, path):
    """A response set's rows resampled onto a uniform grid when its stamps jitter or drop samples
    (:func:`jflex.data.resample_uniform`); ``(arrays, sampling report or None)``. Malformed
    fields are left to :func:`response_arrays` to name."""
    try:
        t = np.asarray(arrs["t"], float)
        tau, y = np.asarray(arrs["tau"], float), np.asarray(arrs["y"], float)
    except (KeyError, TypeError, ValueError):
        return arrs, None
    if t.ndim != 1 or t.size < 20 or tau.shape[:1] != t.shape or y.shape[:1] != t.shape or \
            not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        return arrs, None
    rows = {"tau": tau, "y": y}
    if "y_repeats" in arrs and np.ndim(arrs["y_repeats"]) == 3 and np.shape(arrs["y_repeats"])[1] == t.size:
        rows["y_repeats"] = np.moveaxis(np.asarray(arrs["y_repeats"], float), 0, 1)
    t2, rows, report = resample_uniform(t, rows, str(path))
    if not report["resampled"]:
        return arrs, report
    out = {**arrs, "t": t2, "tau": rows["tau"], "y": rows["y"]}
    if "y_repeats" in rows:
        out["y_repeats"] = np.moveaxis(rows["y_repeats"], 1, 0)
    return out, report


def response_motion(t, tau, y, ch, path, joint_names, inverse_dynamics):
    """Joint channels of a response as an equation-error data set: measured angles smoothed and
    differentiated (Savitzky-Golay, cubic), the applied torques as ``tau``. The window puts the
    filter's cutoff at twice the band of the motion, the band read off the angles' spectrum
    against their noise (:func:`jflex.data._signal.motion_band` on the angles' own spectrum).

    The differentiation turns angle noise into coloured torque-residual noise, which the
    residual's own high-frequency content would understate; so the noise of the angles (robust
    spread of their second difference) is propagated instead: ``tau_repeats`` holds the applied
    torques plus the nominal model's torque change under ``RESPONSE_NOISE_DRAWS`` redraws of it.
    """
    from scipy.signal import savgol_filter

    if t.size < 20:
        raise DataError(f"{path}: field 't': need at least 20 samples, got {t.size}")
    dt = np.diff(t)
    if np.any(dt <= 0):
        raise DataError(f"{path}: field 't': time must be strictly increasing")
    if np.max(np.abs(dt - dt.mean())) > 0.01 * dt.mean():
        raise DataError(f"{path}: field 't': joint-angle channels need uniform sampling (steps vary by "
                        f"{100 * np.max(np.abs(dt - dt.mean())) / dt.mean():.1f} %, more than 1 %)")
    h = float(dt.mean())
    q_raw = y[:, [ch.index(j) for j in joint_names]]
    d2 = q_raw[2:] - 2 * q_raw[1:-1] + q_raw[:-2]
    sig = robust_sigma(d2, axis=0) / np.sqrt(6)
    fc = RESPONSE_CUTOFF_FACTOR * motion_band(q_raw, h, sig, spectrum="angles")
    # Savitzky-Golay of order p and half-width m has its -3 dB point near (p + 1) / (3.2 m - 4.6)
    # x Nyquist (Schafer 2011)
    p = RESPONSE_SG_ORDER
    m = int(np.clip(((p + 1) * (0.5 / h) / fc + 4.6) / 3.2, p, (t.size - 1) // 2))
    win = 2 * m + 1

    def derive(qr):
        return tuple(savgol_filter(qr, win, p, deriv=k, delta=h, axis=0) for k in range(3))

    q, qd, qdd = derive(q_raw)
    rng = np.random.default_rng(0)
    F0 = inverse_dynamics(q, qd, qdd)
    reps = []
    for _ in range(RESPONSE_NOISE_DRAWS):
        qk, qdk, qddk = derive(q + sig * rng.standard_normal(q.shape))
        reps.append(tau + inverse_dynamics(qk, qdk, qddk) - F0)
    return {"q": q, "qd": qd, "qdd": qdd, "q_extra": np.zeros((t.size, 0)), "tau_repeats": np.stack(reps),
            "angle_noise_rad": sig, "cutoff_hz": fc, "window_samples": win}
