"""The noise floor of each validation data set: the NRMSE [%] that measurement noise alone would
leave (from repeated records, what an angle-only log's processing predicts, or the residual's
high-frequency content)."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from ...data._signal import robust_sigma
from ..frequency import _model as L
from ._black_box import black_box_noise
from ._periodic import periodic_noise, repeating_processing_error
from ._view import ProblemView

if TYPE_CHECKING:
    from ..case._case import Case

def repeats_factor(rep, x) -> float:
    """sqrt(R) when the record ``x`` is the mean of its ``R`` repeats (its noise is that of one
    repeat over sqrt(R)), else 1 (a record of its own)."""
    R = rep.shape[0]
    if R > 1 and np.allclose(rep.mean(axis=0), x, rtol=1e-9, atol=1e-12 * float(np.max(np.abs(x)) or 1.0)):
        return float(np.sqrt(R))
    return 1.0


@dataclasses.dataclass(frozen=True)
class NoiseFloor:
    """The noise floor of each validation data set (:func:`noise_floor`): ``per_dataset`` the floor
    [%] (0 where the estimate failed), ``sources`` the method used, ``details`` per set ``method``,
    ``floor``, its interval ``low``/``high``, ``dof``, ``channels`` (each channel's floor [%]),
    ``channel_dof`` and ``failed`` (with ``reason``)."""

    per_dataset: dict
    sources: dict
    details: dict

    @property
    def failed(self) -> dict:
        """``{set: why}`` of the sets whose floor could not be estimated."""
        return {k: v["reason"] for k, v in self.details.items() if v.get("failed")}

    def channel_floors(self) -> dict:
        """``{set: {channel: floor %}}``."""
        return {k: dict(v.get("channels", {})) for k, v in self.details.items()}

    def upper(self) -> dict:
        """``{set: %}``: the upper ends of the floors' confidence intervals, where known."""
        return {k: v["high"] for k, v in self.details.items() if v.get("high") is not None}


def noise_floor(problem: ProblemView, ev: dict, case: Case) -> NoiseFloor:
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
    Returns a :class:`NoiseFloor`: per data set the floor, the method used (``sources``) and
    ``details``: ``method``, ``floor``, its 95 % interval ``low``/``high`` (chi-square on the
    variance estimate, ``dof`` effective degrees of freedom), ``channels`` (each channel's floor
    [%]), and ``failed`` with ``reason`` when the estimate is unusable (0, not finite, or at least
    a trivial model's gap, 100 %): the floor is then unknown (reported 0).
    """
    out, src, det = {}, {}, {}
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
                    prop = repeating_processing_error(s, m, sig)
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
    return NoiseFloor(out, src, det)


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
