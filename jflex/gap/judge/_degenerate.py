"""Data without signal: channels and data sets that cannot be the basis of a verdict.

A torque channel whose measured torque has no spread (all zeros, a constant), holds non-finite
values, or whose spread overflows, normalises its gap by nothing: its NRMSE is an artefact
(``rms(e) / 0``), not a measurement. Such a channel is left out of the gap and named; a data set
left with no channel, or whose torques are orders of magnitude off the nominal model's (a unit or
scale error, or a record without motion), is refused with a :class:`jflex.DataError` naming it.
An FRF set whose measured receptance has no energy is refused likewise."""

from __future__ import annotations

import numpy as np

from ..._errors import DataError

# the measured torque's pooled spread against the nominal (CAD) model's along the same motion:
# outside this range the record is in other units, scaled wrongly, or has no motion
SCALE_RANGE = (1e-3, 1e3)
# a channel whose spread is below this fraction of the set's pooled nominal spread carries no
# signal (a dead sensor reads a constant, or zeros)
DEAD_FRACTION = 1e-9


def _spread(x) -> np.ndarray:
    """Per-column standard deviation, inf when it overflows, NaN when a value is not finite."""
    x = np.asarray(x, float)
    fin = np.all(np.isfinite(x), axis=0)
    x = np.where(np.isfinite(x), x, 0.0)
    with np.errstate(over="ignore", invalid="ignore"):
        m = np.max(np.abs(x), axis=0)
        m = np.where(m > 0, m, 1.0)
        # scaled first: the spread of values near 1e300 overflows when squared
        sd = (x / m).std(axis=0) * m
    return np.where(fin, np.where(np.isfinite(sd), sd, np.inf), np.nan)


def torque_channels(name: str, tau, F0, names) -> tuple[dict, str | None]:
    """``({channel: reason}, set_reason)`` of one torque record: the channels without signal, and
    why the whole set is unusable (None when it is usable). ``tau`` (N, n) is the measured torque,
    ``F0`` (N, n) the nominal model's along the same motion."""
    sd = _spread(tau)
    nom = np.sqrt(np.mean(np.asarray(F0, float).std(axis=0) ** 2))
    bad = {}
    for j, ch in enumerate(names):
        if np.isnan(sd[j]):
            bad[ch] = "non-finite torque values"
        elif np.isinf(sd[j]):
            bad[ch] = "torque spread overflows (values near the float64 limit)"
        elif sd[j] <= DEAD_FRACTION * max(nom, 1e-300):
            bad[ch] = f"no signal: the torque is constant ({float(np.asarray(tau)[0, j]) + 0.0:.4g} N m throughout)"
    if len(bad) == len(names):
        return bad, "no channel carries a torque signal (" + "; ".join(f"{c}: {r}" for c, r in bad.items()) + ")"
    ok = [j for j, ch in enumerate(names) if ch not in bad]
    top = float(np.max(sd[ok]))
    meas = np.sqrt(np.mean((sd[ok] / top) ** 2)) * top  # scaled: squares of values near 1e300 overflow
    if nom <= 0 or not (SCALE_RANGE[0] <= meas / nom <= SCALE_RANGE[1]):
        ratio = meas / nom if nom > 0 else np.inf
        return bad, (f"its torque spread ({meas:.3g} N m pooled) is {ratio:.3g} times the nominal model's "
                     f"({nom:.3g} N m) along the same motion, outside {SCALE_RANGE[0]:g}..{SCALE_RANGE[1]:g}: "
                     "torques in other units or scaled wrongly (a motor current's scale), or a record without motion")
    return bad, None


def frf_set(H) -> str | None:
    """Why a measured FRF (F, 3, 3) is unusable (None when it is usable)."""
    H = np.asarray(H)
    if not np.all(np.isfinite(H)):
        return "non-finite receptance values"
    with np.errstate(over="ignore"):
        e = float(np.sum(np.abs(H / max(float(np.max(np.abs(H))), 1e-300)) ** 2))
    if not np.any(H != 0) or not np.isfinite(e) or e <= 0:
        return "the measured receptance is zero throughout (no signal)"
    return None


def refuse(found: list) -> None:
    """Raise :class:`jflex.DataError` naming every data set without signal in ``found``
    (``[(dataset name, reason)]``); nothing when it is empty."""
    if found:
        raise DataError("data without signal cannot be the basis of a verdict: " +
                        "; ".join(f"data set '{n}': {r}" for n, r in found) +
                        " (fix the data set's scale or units, or leave it out of the case)")
