"""Signal processing of measured joint positions (seed 003 section 3.2.5): FFT low-pass
filtering and spectral differentiation of periodic records."""

from __future__ import annotations

import numpy as np

from .._errors import DataError
from ._data import check_finite


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
