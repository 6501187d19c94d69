"""The frequency side of the gap diagnosis: the model of elastic sites at the measured postures
(:class:`FrequencyModel`, in :mod:`._elastic_model`, its sites, laws and tool payload in
:mod:`._sites`, :mod:`._laws`, :mod:`._payload`) and its fit to measured FRFs and modal tables
(the residuals and :func:`fit_linear`, here). The diagnosis reads every name of the frequency
side from this module.
"""

from __future__ import annotations

import numpy as np
import scipy.optimize as so

# the frequency side's names, read by the diagnosis as ``L.<name>`` (``from .frequency import _model as L``)
from ...effects import KelvinVoigt  # noqa: F401
from ._elastic_model import FrequencyModel, PostureMats, Structure, _elastic_linearization, _gen_eig, _quiet  # noqa: F401
from ._laws import VISCOUS, frequency_dependent, law_key, law_name, unit_loss, with_loss  # noqa: F401
from ._payload import PAYLOAD_COM_BOX, PAYLOAD_NAMES, payload_inertia, payload_start  # noqa: F401
from ._sites import Site, augment  # noqa: F401


# --- data residuals ----------------------------------------------------------------------------
def match_modes(f_model, f_meas, return_assigned: bool = False):
    """Assign measured modes to model modes by relative frequency distance (one-to-one where the
    model has modes left; a measured mode beyond the model's count takes its nearest mode).

    Returns ``(index (M,), relative error (M,))``."""
    from scipy.optimize import linear_sum_assignment

    M = len(f_meas)
    if len(f_model) == 0:
        return (np.full(M, -1), np.ones(M), np.zeros(M, bool)) if return_assigned else (np.full(M, -1), np.ones(M))
    cost = np.abs(f_model[None, :] - f_meas[:, None]) / f_meas[:, None]
    cost = np.where(np.isfinite(cost), cost, 1e6)
    rows, cols = linear_sum_assignment(cost)
    idx = np.full(M, -1)
    idx[rows] = cols
    assigned = idx >= 0
    for i in range(M):
        if idx[i] < 0:
            idx[i] = int(np.argmin(cost[i]))
    rel = (f_model[idx] - f_meas) / f_meas
    if return_assigned:
        return idx, rel, assigned
    return idx, rel


DAMPING_WEIGHT = 0.1  # a 10 % damping-ratio misfit counts like a 1 % frequency misfit


def modal_errors(lm: FrequencyModel, x, arr, fitting: bool = False):
    """Relative frequency and damping errors of a modal table. When ``fitting``, measured modes
    left over after the one-to-one assignment (the model has fewer modes) do not pull the fit:
    they are the gap a candidate must explain, not something the nominal stiffness should
    compromise for."""
    f, z = lm.modes(x, arr["q0"])
    idx, ef, assigned = match_modes(f, arr["freq"], return_assigned=True)
    if fitting:
        ef = np.where(assigned, ef, 0.0)
    zm = arr["zeta"]
    ok = np.isfinite(zm)
    ez = np.zeros_like(ef)
    if len(f):
        ez[ok] = (z[idx][ok] - zm[ok]) / np.maximum(zm[ok], 0.005)
    if fitting:
        ez = np.where(assigned, ez, 0.0)
    return ef, ez, idx, f, z


def frf_scale(H):
    """Per-entry RMS magnitude (3, 3) of a measured FRF."""
    return np.sqrt(np.mean(np.abs(H) ** 2, axis=0))


def frf_entries(H):
    s = frf_scale(H)
    return s > 1e-3 * s.max()


def _frf_norm(a):
    """(entries used, normalisation) of a measured FRF set's residual, kept with its arrays."""
    if "_norm" not in a:
        H = a["H"]
        s, ok = frf_scale(H), frf_entries(H)
        n = len(H[::FIT_STRIDE])
        a["_norm"] = (ok, np.sqrt(np.mean(s[ok] ** 2)) * np.sqrt(n * ok.sum()))
    return a["_norm"]


def frf_peaks(freq, H, prominence=0.03):
    """Peaks of the summed normalised magnitude of a measured FRF (smoothed over three lines):
    (f [Hz], zeta) by peak picking and the half-power bandwidth on the frequency grid (NaN when a
    half-power point is off the grid; :func:`jflex.data._peaks.pick_peaks`)."""
    from ...data._peaks import pick_peaks

    s = frf_scale(H)
    ok = frf_entries(H)
    mag = (np.abs(H[:, ok]) / s[ok]).sum(axis=1)
    mag = np.convolve(np.pad(mag, 1, mode="edge"), np.ones(3) / 3, mode="valid")
    return pick_peaks(freq, mag, prominence, half_power="grid")[:2]


PEAK_WEIGHT = 1.0  # FRF training sets also enter through their picked peaks (smooth in log k)
RECENTRE = 2  # times the FRF phase may move its box to a stiffness that ended on the edge
# relative cost change at which an FRF fit stops: gaps are judged to 0.01 % of NRMSE; scipy's 1e-8
# default ran most FRF fits to their evaluation cap (modal-table fits are cheap and keep it: their few
# residuals leave flat directions that stopped early at 1e-6, e.g. the thesis' KR90 bearing 9.0 -> 9.6 %)
FIT_TOL = 1e-6
FIT_STRIDE = 4  # every 4th frequency of a measured FRF enters the fit (peaks stay resolved)


def residual(lm: FrequencyModel, x, train, peaks_only: bool = False, peaks: bool = True) -> np.ndarray:
    """Stacked fitting residual of the training FRF and modal sets: FRFs as the complex error
    normalised by the set's RMS magnitude over its entries, i.e. the FRF NRMSE the gap is judged
    by (a log-ratio misfit was tried and preferred sharp misplaced peaks; a per-entry
    normalisation let the small cross entries outweigh the dominant ones, so a fit could lower
    its cost while the judged gap doubled), modal tables as relative frequency errors plus a
    weighted damping error. FRF sets also enter through their picked peaks (``peaks``; alone
    with ``peaks_only``): smooth in log k, but the half-power damping of overlapping peaks is
    biased, so the final phase of :func:`fit_linear` leaves them out."""
    out = []
    for d in train:
        a = d.arrays
        if d.kind == "frf":
            if peaks_only:
                e = np.zeros(0, complex)  # (no FRF evaluated: the peaks alone enter)
            else:
                sl = slice(None, None, FIT_STRIDE)
                H = a["H"][sl]
                Hm = lm.frf(x, a["q0"], a["freq"][sl])
                ok, norm = _frf_norm(a)
                e = (Hm[:, ok] - H[:, ok]) / norm
            if peaks and "_peaks" not in a:
                a["_peaks"] = frf_peaks(a["freq"], a["H"])
            pf, pz = a["_peaks"] if peaks else ((), ())
            if len(pf):
                fm, zm = lm.modes(x, a["q0"])
                idx, ef, assigned = match_modes(fm, pf, return_assigned=True)
                ef = np.where(assigned, ef, 0.0)
                okz = np.isfinite(pz) & assigned
                ez = np.zeros_like(ef)
                if len(fm):
                    ez[okz] = (zm[idx][okz] - pz[okz]) / np.maximum(pz[okz], 0.005)
                out += [PEAK_WEIGHT * ef / np.sqrt(len(ef)), PEAK_WEIGHT * DAMPING_WEIGHT * ez / np.sqrt(len(ez))]
            out += [e.real.ravel(), e.imag.ravel()]
        elif d.kind == "modal":
            ef, ez, *_ = modal_errors(lm, x, a, fitting=True)
            out += [ef / np.sqrt(len(ef)), DAMPING_WEIGHT * ez / np.sqrt(len(ez))]
    r = np.concatenate(out) if out else np.zeros(0)
    return np.where(np.isfinite(r), r, 1e3)


def residual_jacobian(lm: FrequencyModel, x, train):
    """:func:`residual` without the peaks (``peaks=False``) and its Jacobian in ``x``, for training
    sets that are all FRFs (None otherwise: modal tables go by finite differences)."""
    if not train or any(d.kind != "frf" for d in train):
        return None
    rows, jac = [], []
    for d in train:
        a = d.arrays
        sl = slice(None, None, FIT_STRIDE)
        H = a["H"][sl]
        Hm, dH = lm.frf_jacobian(x, a["q0"], a["freq"][sl])
        ok, norm = _frf_norm(a)
        e = (Hm[:, ok] - H[:, ok]) / norm
        de = dH[:, :, ok] / norm
        rows += [e.real.ravel(), e.imag.ravel()]
        jac += [de.real.reshape(len(x), -1), de.imag.reshape(len(x), -1)]
    r = np.concatenate(rows)
    Jr = np.concatenate(jac, axis=1).T
    bad = ~np.isfinite(r)
    r = np.where(bad, 1e3, r)
    Jr = np.where(np.isfinite(Jr) & ~bad[:, None], Jr, 0.0)
    return r, Jr


def fit_linear(lm: FrequencyModel, x0, train, free=None, starts=(), peaks_first: bool = True):
    """Nonlinear least squares (log parameters) from ``x0`` and extra starting points ``starts``;
    ``free`` masks the parameters to fit (the rest held); ``peaks_first``: a first phase on the
    picked peaks alone (for starts whose modes may lie far from the measured ones)."""
    x0 = np.asarray(x0, float)
    free = np.ones_like(x0, bool) if free is None else np.asarray(free, bool)
    best = None
    phases = (True, False) if peaks_first and any(d.kind == "frf" for d in train) else (False,)
    for xs in (x0, *starts):
        xs = np.asarray(xs, float)
        # the box is centred on the start for both phases: re-centred on the peaks phase's result,
        # it trapped the FRF phase where the biased peak damping had pushed a parameter to its edge
        u0 = np.clip(xs[free], -50, 50)
        # two phases: the picked peaks alone (smooth in log k), then the whole complex FRF without
        # the peaks (their half-power damping is biased where peaks overlap)
        for peaks_only in phases:
            def fun(u, xs=xs, po=peaks_only):
                x = xs.copy()
                x[free] = u
                return residual(lm, x, train, po, peaks=po)

            # the FRF phase: analytic Jacobian (FRF sets only), else finite differences
            exact = not peaks_only and all(d.kind == "frf" for d in train)
            tol = dict(ftol=FIT_TOL, xtol=FIT_TOL, gtol=FIT_TOL) if exact else {}

            def jac(u, xs=xs):
                x = xs.copy()
                x[free] = u
                return residual_jacobian(lm, x, train)[1][:, free]

            if not free.any():
                break
            # log parameters stay within a factor e^3 (stiffness) / e^4 (damping) of the start: the
            # FRF misfit has spurious minima at vanishing or huge damping (FrequencyModel.widths)
            width = lm.widths()[free]
            alo, ahi = (b[free] for b in lm.absolute_bounds())
            fixed = np.isfinite(alo)
            # lsmr: no dense SVD of the Jacobian per step (that SVD dominated, and stalls when BLAS
            # threads contend for shared cores)
            centre = u0
            for _ in range(1 + (0 if peaks_only else RECENTRE)):
                lo, hi = centre - width, centre + width
                if fixed.any():
                    lo, hi = np.where(fixed, alo, lo), np.where(fixed, ahi, hi)
                # (lsmr's 2-D subspace step fails on a single free parameter: exact there)
                sol = so.least_squares(fun, np.clip(xs[free], lo, hi), jac=jac if exact else "2-point", method="trf",
                                       bounds=(lo, hi), tr_solver="lsmr" if free.sum() > 1 else "exact",
                                       max_nfev=15 * (1 + free.sum()), **tol)
                xs = xs.copy()
                xs[free] = sol.x
                # a stiffness that stops on the box's edge (a new compliance the nominal springs had
                # absorbed: they stiffen as it softens) moves the box there, a bounded number of
                # times; damping keeps its box (moved, it ran to the spurious minimum at vanishing
                # damping: a sharp peak between the fitted frequencies)
                edge = (np.abs(sol.x - lo) < 1e-6) | (np.abs(sol.x - hi) < 1e-6)
                if not np.any(edge & (width == 3.0)):
                    break
                centre = np.where(width == 3.0, sol.x, centre)
        r = residual(lm, xs, train, peaks=False)
        cand = (float(r @ r), xs)
        if best is None or cand[0] < best[0]:
            best = cand
    # a fit that ends worse than where it started (the peaks phase can lead astray) keeps the start
    r = residual(lm, x0, train, peaks=False)
    if float(r @ r) < best[0]:
        best = (float(r @ r), x0)
    return best[1], best[0]
