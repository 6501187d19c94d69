"""Experimental modal analysis helpers: FRF estimation from time data (H1/H2, windows,
averaging, coherence), modal parameters from FRFs (peak picking with half-power damping; the
least-squares complex-frequency (LSCF, "polymax"-type) common-denominator fit with a
stabilisation check; least-squares residues for mode shapes). MAC: :func:`jflex.mac`."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._errors import DataError
from ..data._peaks import pick_peaks
from ..data._validate import check_finite


class FRFEstimate(NamedTuple):
    """``freq`` (nf,) [Hz]; ``H`` (nf, no) complex [output unit / input unit]; ``coherence``
    (nf, no) in [0, 1]; ``n_averages``."""

    freq: np.ndarray
    H: np.ndarray
    coherence: np.ndarray
    n_averages: int


def _window(window, n):
    if isinstance(window, np.ndarray):
        if window.shape != (n,):
            raise DataError(f"frf_estimate: a window array must have shape ({n},), got {window.shape}")
        return window
    if isinstance(window, tuple) and window[0] == "exponential":
        # Hammer tests: decay to window[1] (e.g. 0.01) of its start at the record end.
        return np.exp(np.log(window[1]) * np.arange(n) / (n - 1))
    import scipy.signal  # loaded here: it costs seconds at import and only EMA needs it

    return scipy.signal.get_window(window, n, fftbins=True)


def frf_estimate(x, y, fs: float, *, nperseg: int | None = None, overlap: float = 0.5, window="hann",
                 estimator: str = "H1") -> FRFEstimate:
    """Estimate FRFs from input ``x`` and outputs ``y`` with Welch averaging.

    **Arguments:**

    - ``x`` (N,) or (R, N): input (force) [N]; R records (e.g. hammer hits) are averaged.
    - ``y`` (N, no) or (R, N, no) (or (N,)): outputs, sampled with ``x`` at ``fs`` [Hz].
    - ``nperseg``: segment length (default: the record length, one segment per record).
    - ``overlap``: fraction of segment overlap; ``window``: a scipy window name, an array, or
      ``("exponential", end_value)`` for impact tests.
    - ``estimator``: ``"H1"`` (``G_xy / G_xx``: unbiased by output noise) or ``"H2"``
      (``G_yy / G_yx``: unbiased by input noise).

    **Returns:** :class:`FRFEstimate` with the ordinary coherence ``|G_xy|^2 / (G_xx G_yy)``.
    """
    x = check_finite(x, "x").astype(float)
    y = check_finite(y, "y").astype(float)
    if x.ndim == 1:
        x = x[None]
        y = y[None]
    if y.ndim == 2:
        y = y[..., None]
    if y.shape[:2] != x.shape:
        raise DataError(f"frf_estimate: x has {x.shape} (records, samples) but y has {y.shape[:2]}; they must match")
    if estimator not in ("H1", "H2"):
        raise DataError(f"frf_estimate: estimator must be 'H1' or 'H2', got '{estimator}'")
    N = x.shape[1]
    L = N if nperseg is None else int(nperseg)
    if not 4 <= L <= N:
        raise DataError(f"frf_estimate: nperseg must be between 4 and the record length {N}, got {L}")
    step = max(1, int(round(L * (1 - overlap))))
    w = _window(window, L)
    Gxx = 0.0
    Gyy = 0.0
    Gxy = 0.0
    count = 0
    for r in range(x.shape[0]):
        for s in range(0, N - L + 1, step):
            X = np.fft.rfft(w * x[r, s : s + L])
            Y = np.fft.rfft(w[:, None] * y[r, s : s + L], axis=0)
            Gxx = Gxx + np.abs(X) ** 2
            Gyy = Gyy + np.abs(Y) ** 2
            Gxy = Gxy + np.conj(X)[:, None] * Y
            count += 1
    Gxx = Gxx[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        H = Gxy / Gxx if estimator == "H1" else Gyy / np.conj(Gxy)
        coh = np.abs(Gxy) ** 2 / (Gxx * Gyy)
    return FRFEstimate(np.fft.rfftfreq(L, 1.0 / fs), H, np.nan_to_num(coh), count)


def _magnitude(H):
    H = np.asarray(H)
    return np.abs(H) if H.ndim == 1 else np.sqrt((np.abs(H.reshape(H.shape[0], -1)) ** 2).sum(axis=1))


def peak_picking(freq, H, n_modes: int | None = None, *, freq_range=None, prominence: float = 0.05):
    """Natural frequencies at the peaks of |H| and damping by the half-power bandwidth.

    ``zeta = (f_2 - f_1) / (2 f_n)`` with ``f_1, f_2`` where |H| crosses ``|H|_peak / sqrt(2)``
    (linear interpolation). With several channels (nf, ...) the root-sum-square magnitude is used.

    **Arguments:** ``freq`` (nf,) [Hz]; ``H`` (nf,) or (nf, ...); ``n_modes``: keep the most
    prominent; ``freq_range`` (lo, hi) [Hz]; ``prominence`` relative to the largest peak.

    **Returns:** ``(f_n (k,) [Hz], zeta (k,), index (k,))``, sorted by frequency; zeta is NaN when
    a half-power point falls off the band.
    """
    freq = check_finite(freq, "freq").astype(float)
    A = _magnitude(H)
    if A.shape[0] != freq.shape[0]:
        raise DataError(f"peak_picking: freq has {freq.shape[0]} points but H has {A.shape[0]}")
    mask = np.ones_like(freq, bool) if freq_range is None else (freq >= freq_range[0]) & (freq <= freq_range[1])
    return pick_peaks(freq, A, prominence, search=np.where(mask, A, 0.0), n_modes=n_modes)


class LSCFResult(NamedTuple):
    """Poles per model order: ``orders`` (list of int); ``frequency``, ``damping``, ``stable``:
    lists (one array per order) [Hz], [-], bool (stable in frequency and damping with respect
    to the previous order)."""

    orders: list
    frequency: list
    damping: list
    stable: list


def lscf(freq, H, orders=range(2, 41, 2), *, freq_range=None, tol_f: float = 0.01, tol_z: float = 0.05) -> LSCFResult:
    """Least-squares complex-frequency fit (common denominator, z-domain basis) at several orders.

    ``H_o(w) = N_o(Omega) / A(Omega)`` with ``Omega = exp(-i w dt)``, ``dt = pi / w_max``; the
    numerators are eliminated from the normal equations (reduced equations), ``A`` has real
    coefficients with the highest one fixed to 1, and the poles ``s = -ln(Omega_r) / dt`` follow
    from the roots of ``A``. A pole is *stable* at an order when the previous order has one within
    ``tol_f`` (relative) in frequency and ``tol_z`` (relative) in damping.

    **Arguments:** ``freq`` (nf,) [Hz]; ``H`` (nf,) or (nf, no) complex (one reference);
    ``orders``: denominator orders; ``freq_range`` (lo, hi) [Hz].

    **Returns:** :class:`LSCFResult` (physical poles only: Im s > 0, Re s < 0).
    """
    freq = check_finite(freq, "freq").astype(float)
    H = check_finite(H, "H").astype(complex)
    if H.ndim == 1:
        H = H[:, None]
    H = H.reshape(H.shape[0], -1)
    if H.shape[0] != freq.shape[0]:
        raise DataError(f"lscf: freq has {freq.shape[0]} points but H has {H.shape[0]}")
    if freq_range is not None:
        sel = (freq >= freq_range[0]) & (freq <= freq_range[1])
        freq, H = freq[sel], H[sel]
    w = 2 * np.pi * freq
    dt = np.pi / w.max()
    res_f, res_z, res_s, ords = [], [], [], []
    prev = None
    for p in orders:
        p = int(p)
        Om = np.exp(-1j * np.outer(w, np.arange(p + 1)) * dt)  # (nf, p+1)
        R = np.real(Om.conj().T @ Om)
        Rinv = np.linalg.pinv(R)
        M = np.zeros((p + 1, p + 1))
        for o in range(H.shape[1]):
            Y = -H[:, o : o + 1] * Om
            S = np.real(Om.conj().T @ Y)
            T = np.real(Y.conj().T @ Y)
            M += T - S.T @ Rinv @ S
        alpha = np.ones(p + 1)
        alpha[:p] = -np.linalg.lstsq(M[:p, :p], M[:p, p], rcond=None)[0]
        roots = np.roots(alpha[::-1])
        s = -np.log(roots.astype(complex)) / dt
        s = s[(s.imag > 0) & (s.real < 0)]
        f = np.abs(s) / (2 * np.pi)
        z = -s.real / np.abs(s)
        order = np.argsort(f)
        f, z = f[order], z[order]
        st = np.zeros(f.shape, bool)
        if prev is not None and len(prev[0]):
            for i in range(len(f)):
                k = np.argmin(np.abs(prev[0] - f[i]))
                st[i] = abs(prev[0][k] - f[i]) <= tol_f * f[i] and abs(prev[1][k] - z[i]) <= tol_z * z[i]
        prev = (f, z)
        ords.append(p)
        res_f.append(f)
        res_z.append(z)
        res_s.append(st)
    return LSCFResult(ords, res_f, res_z, res_s)


def stable_modes(result: LSCFResult, *, min_count: int = 4, tol_f: float = 0.01):
    """Modes that stay stable over at least ``min_count`` orders of a stabilisation diagram.

    **Returns:** ``(f (k,) [Hz], zeta (k,))``: medians of each cluster of stable poles.
    """
    pts = [(f, z) for fs, zs, ss in zip(result.frequency, result.damping, result.stable) for f, z, s in zip(fs, zs, ss) if s]
    if not pts:
        return np.zeros(0), np.zeros(0)
    pts = sorted(pts)
    clusters = [[pts[0]]]
    for f, z in pts[1:]:
        if abs(f - clusters[-1][-1][0]) <= tol_f * f:
            clusters[-1].append((f, z))
        else:
            clusters.append([(f, z)])
    good = [np.median(np.array(c), axis=0) for c in clusters if len(c) >= min_count]
    if not good:
        return np.zeros(0), np.zeros(0)
    g = np.array(good)
    return g[:, 0], g[:, 1]


def modal_residues(freq, H, frequency, damping, *, residual_terms: bool = True):
    """Least-squares residues (mode shapes) for known poles (LSFD).

    ``H(w) = sum_r [A_r / (i w - s_r) + conj(A_r) / (i w - conj(s_r))] (+ LR / w^2 + UR)``.

    **Arguments:** ``freq`` (nf,) [Hz]; ``H`` (nf,) or (nf, no) receptance-like; ``frequency``
    (m,) [Hz], ``damping`` (m,) the poles.

    **Returns:** complex residues (no, m): column r is the (unscaled) shape of mode r.
    """
    freq = np.asarray(freq, float)
    H = np.asarray(H, complex)
    if H.ndim == 1:
        H = H[:, None]
    wn = 2 * np.pi * np.asarray(frequency, float)
    z = np.asarray(damping, float)
    s = -z * wn + 1j * wn * np.sqrt(np.maximum(1 - z**2, 0))
    iw = 2j * np.pi * freq
    cols = []
    for sr in s:
        cols += [1 / (iw - sr) + 1 / (iw - np.conj(sr)), 1j / (iw - sr) - 1j / (iw - np.conj(sr))]
    if residual_terms:
        cols += [-1 / np.where(freq > 0, (2 * np.pi * freq) ** 2, np.inf), np.ones_like(freq)]
    B = np.stack(cols, axis=1)
    Bri = np.concatenate([B.real, B.imag])
    Hri = np.concatenate([H.real, H.imag])
    c, *_ = np.linalg.lstsq(Bri, Hri, rcond=None)
    m = len(s)
    return (c[0 : 2 * m : 2] + 1j * c[1 : 2 * m : 2]).T
