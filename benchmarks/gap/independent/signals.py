"""Signals of the independent bench: excitation trajectories, encoder quantisation, coloured
noise and the H1 estimate of an FRF from simulated input/output records (NumPy + SciPy)."""

from __future__ import annotations

import numpy as np
from scipy import signal


class Fourier:
    """A periodic joint trajectory ``q(t) = c + sum_k a_k sin(w_k t) + b_k cos(w_k t)`` with exact
    derivatives at any time (the robot is assumed to track it: the data come from its
    inverse dynamics or from a simulation that takes it as the motor motion)."""

    def __init__(self, rng, center, amp, f0=0.2, harmonics=5):
        center = np.asarray(center, float)
        n = center.size
        self.c = center
        self.w = 2 * np.pi * f0 * np.arange(1, harmonics + 1)
        a = rng.normal(size=(n, harmonics)) / np.arange(1, harmonics + 1)
        b = rng.normal(size=(n, harmonics)) / np.arange(1, harmonics + 1)
        # scaled by the sum of |coefficients|: the excursion never exceeds amp (joint limits hold)
        s = np.asarray(amp, float).reshape(-1, 1) / np.sum(np.abs(a) + np.abs(b), axis=1, keepdims=True)
        self.a, self.b = a * s, b * s

    def __call__(self, t, d: int = 0):
        """``d``-th time derivative at times ``t`` (N,): (N, n)."""
        t = np.atleast_1d(np.asarray(t, float))[:, None, None]
        w = self.w[None, None, :]
        # d-th derivative of sin/cos: a phase shift of d * pi / 2 and a factor w^d
        ph = d * np.pi / 2
        val = (self.a[None] * np.sin(w * t + ph) + self.b[None] * np.cos(w * t + ph)) * w**d
        out = val.sum(axis=2)
        return out + self.c[None] if d == 0 else out


def quantise(q, step):
    """Encoder reading: ``q`` rounded to multiples of ``step`` [rad]."""
    return np.round(np.asarray(q) / step) * step


def ar1_noise(rng, shape, pole, std):
    """AR(1) (first-order coloured) noise of pole ``pole`` and standard deviation ``std`` per column."""
    N, n = shape
    burn = int(10 / (1 - pole))  # the filter forgets its zero start
    w = rng.standard_normal((N + burn, n))
    e = signal.lfilter([1.0], [1.0, -pole], w, axis=0)[burn:]
    return e / e.std(axis=0) * np.asarray(std)[None, :]


def h1_frf(H_of_f, fs, n_samples, nperseg, rng, in_noise=0.02, out_noise=0.03, segments=3):
    """H1 estimates of a 3x3 receptance from a simulated random excitation.

    ``H_of_f(f)`` (F,) -> (F, 3, 3) is the true FRF (output x input). Three uncorrelated random
    forces (Gaussian spectra on the FFT grid of a periodic record of ``n_samples`` at ``fs``) drive
    it; the outputs are the inverse FFT of ``H X``. Measured input and output get white noise of
    ``in_noise`` / ``out_noise`` times their standard deviations. The record is split into
    ``segments`` parts; each gives ``H1 = G_yx G_xx^-1`` (Welch cross-spectra, Hann windows of
    ``nperseg``). Returns ``(f, H1 per segment (segments, F, 3, 3))``.
    """
    fgrid = np.fft.rfftfreq(n_samples, 1.0 / fs)
    X = (rng.standard_normal((3, fgrid.size)) + 1j * rng.standard_normal((3, fgrid.size)))
    X[:, 0] = 0.0
    Hg = np.zeros((fgrid.size, 3, 3), complex)
    Hg[1:] = H_of_f(fgrid[1:])
    Y = np.einsum("fij,jf->if", Hg, X)
    x = np.fft.irfft(X, n_samples, axis=1)
    y = np.fft.irfft(Y, n_samples, axis=1)
    x = x + in_noise * x.std(axis=1, keepdims=True) * rng.standard_normal(x.shape)
    y = y + out_noise * y.std(axis=1, keepdims=True) * rng.standard_normal(y.shape)
    out = []
    L = n_samples // segments
    for s in range(segments):
        xs, ys = x[:, s * L:(s + 1) * L], y[:, s * L:(s + 1) * L]
        f, _ = signal.csd(xs[0], xs[0], fs=fs, nperseg=nperseg)
        Gxx = np.empty((f.size, 3, 3), complex)
        Gyx = np.empty((f.size, 3, 3), complex)
        for i in range(3):
            for j in range(3):
                # scipy's csd(a, b) estimates conj(A) B: G_xx[i, j] = E[X_i conj(X_j)] is csd(x_j, x_i)
                Gxx[:, i, j] = signal.csd(xs[j], xs[i], fs=fs, nperseg=nperseg)[1]
                Gyx[:, i, j] = signal.csd(xs[j], ys[i], fs=fs, nperseg=nperseg)[1]
        H1 = np.full((f.size, 3, 3), np.nan + 0j)
        ok = f > 0
        H1[ok] = Gyx[ok] @ np.linalg.inv(Gxx[ok])
        out.append(H1)
    return f, np.stack(out)
