"""The noise floor of each validation data set: the NRMSE [%] that measurement noise alone would
leave (from repeated records, what an angle-only log's processing predicts, or the residual's
high-frequency content)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from . import _frequency_model as L

if TYPE_CHECKING:
    from ._case import Case
    from ._problem import Problem

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


def noise_floor(problem: Problem, ev: dict, case: Case, sources: dict | None = None) -> dict:
    """NRMSE [%] that noise alone leaves, per validation data set.

    Torque: from ``tau_repeats`` when recorded (over sqrt(R) when ``tau`` is their mean), else the robust (MAD) spread of the residual's
    second difference, ``sigma = MAD(d2 r) / sqrt(6)`` (white noise: var(d2) = 6 sigma^2; the
    smooth model error barely enters, and the median ignores the few jumps at reversals).
    FRF: ``H_repeats`` when recorded (likewise), else the same on the real and imaginary parts of the
    residual along frequency. Modal tables: :func:`modal_floor`.
    Output-error (tip) sets: ``y_repeats`` when recorded, else per channel the smaller of the
    residual's second-difference estimate and the record's own fourth difference,
    ``MAD(d4 y) / sqrt(70)`` (a nominal simulation that drifts or runs away fast leaves
    high-frequency content in the residual, not in the record; smooth motion barely enters d4).
    ``sources``: optional mapping filled with the estimate used per data set.
    """
    out = {}
    src = {} if sources is None else sources
    by_name = {d.name: d for d in case.datasets}
    for name, r in ev.items():
        d = by_name[name]
        if r["kind"] == "torque":
            s = next(s for s in problem.tval if s.name == name)
            if "tau_repeats" in d.arrays and s.cutoff is None:
                src[name] = "propagated angle noise" if d.kind == "response" else "tau_repeats"
                rep = d.arrays["tau_repeats"]
                sig = rep.std(axis=0, ddof=1).mean(axis=0) / s.scale / repeats_factor(rep, d.arrays["tau"])
            elif "tau_repeats" in d.arrays:
                # repeats of raw torques through the same low-pass as the data
                rep = d.arrays["tau_repeats"]
                rf = np.stack([s.lp(r)[::s.processing.get("decimate", 1)] for r in rep])
                sig = rf.std(axis=0, ddof=1).mean(axis=0) / s.scale / repeats_factor(rep, d.arrays["tau"])
                src[name] = "tau_repeats (filtered)"
            elif s.noise is not None:
                # angle-only log: what the processing predicts (raw torque spectrum above the motion
                # band through the filter, plus the angle noise propagated through the model)
                sig = s.noise / s.scale
                src[name] = "filtered torque spectrum + propagated angle noise"
            else:
                e = r["resid"]
                d2 = e[2:] - 2 * e[1:-1] + e[:-2]
                sig = np.array([robust_sigma(d2[:, j]) / np.sqrt(6) for j in range(e.shape[1])])
                src[name] = "residual second difference"
            out[name] = float(np.sqrt(np.mean(sig**2)) * 100)
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
        elif r["kind"] == "frf":
            out[name], src[name] = frf_floor(d.arrays, r["err"])
        else:
            out[name], src[name] = modal_floor(case, d.arrays.get("zeta"))
    return out


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
