"""Hysteretic damping (seed 004 Eqs. 16-27).

In frequency: the complex stiffness ``K (1 + i eta sign(omega))`` (Eq. 22). In time: a
Masing-rule element (Eqs. 25-27) with the virgin curve ``y(x) = h0 [1 - (delta/(delta + x))^2]``:
on the virgin curve ``F = f(x)`` (odd extension of ``y``); after a reversal at ``(x_m, F_m)``,
``F = F_m + 2 f((x - x_m)/2)``. The reversal memory is kept as three states per element: the
travel since the last reversal ``u``, the force ``F`` and the branch factor ``s`` (1 on the virgin
curve, 2 after the first reversal), integrated as ``dF/dt = y'(|u|/s) dx/dt``. A reversal
(``u dx/dt < 0``) resets ``u`` to 0 at the rate ``reversal_rate`` [1/s] (large: a stiff but
continuous stand-in for the jump), and ``s`` relaxes to 2. The re-joining of the virgin curve
beyond the previous maximum amplitude (the last sentence of the rule after Eq. 26) is not modelled:
in a decaying free vibration the amplitude never exceeds it.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .._errors import ParameterError
from ._damping import AbstractDampingLaw


def virgin_curve(x, h0, delta):
    """Odd extension of ``y = h0 [1 - (delta / (delta + |x|))^2]`` [N]."""
    a = jnp.abs(x)
    return jnp.sign(x) * h0 * (1.0 - (delta / (delta + a)) ** 2)


def masing_force(path, h0, delta) -> np.ndarray:
    """Reference Masing force along a sampled displacement path (N,), by the explicit rule
    (reversal points detected from the samples), for tests and plots."""
    path = np.asarray(path, dtype=float)
    f = lambda x: np.sign(x) * h0 * (1.0 - (delta / (delta + abs(x))) ** 2)
    out = np.zeros_like(path)
    xm, Fm, virgin, d = 0.0, 0.0, True, 0.0
    for i, x in enumerate(path):
        if i > 0:
            dx = x - path[i - 1]
            if d != 0 and dx * d < 0:  # reversal at the previous sample
                xm, Fm, virgin = path[i - 1], out[i - 1], False
            if dx != 0:
                d = np.sign(dx)
        out[i] = f(x) if virgin else Fm + 2 * f((x - xm) / 2)
    return out


class Hysteretic(AbstractDampingLaw):
    """Hysteretic damping: complex stiffness in frequency, Masing element in time.

    **Arguments:** ``eta`` loss factor (frequency domain, Eq. 22); ``h0`` [N] and ``delta`` [m]
    (virgin curve Eq. 27, time domain); ``reversal_rate`` [1/s] of the memory reset (default 1e4).
    The element acts on ``P e`` (the owner's projection, e.g. a beam's tip deflection).
    """

    eta: jnp.ndarray
    h0: jnp.ndarray
    delta: jnp.ndarray
    reversal_rate: jnp.ndarray

    def __init__(self, eta=0.0, h0=0.0, delta=1e-3, reversal_rate=1e4):
        for k, v in {"eta": eta, "h0": h0}.items():
            if not np.isfinite(v) or float(v) < 0:
                raise ParameterError(f"Hysteretic.{k} must be >= 0, got {v}")
        for k, v in {"delta": delta, "reversal_rate": reversal_rate}.items():
            if not np.isfinite(v) or not float(v) > 0:
                raise ParameterError(f"Hysteretic.{k} must be > 0, got {v}")
        self.eta, self.h0 = jnp.asarray(float(eta)), jnp.asarray(float(h0))
        self.delta, self.reversal_rate = jnp.asarray(float(delta)), jnp.asarray(float(reversal_rate))

    def state_suffixes(self, m, r):
        return tuple(f"hyst{i}_{k}" for i in range(r) for k in ("u", "F", "s"))

    def initial_state(self, m, r):
        return jnp.tile(jnp.array([0.0, 0.0, 1.0]), r)

    def loaded_state(self, d0):
        """States after loading from rest along the virgin curve to displacements ``d0`` (r,)."""
        d0 = jnp.atleast_1d(jnp.asarray(d0, dtype=float))
        F0 = virgin_curve(d0, self.h0, self.delta)
        return jnp.stack([d0, F0, jnp.ones_like(d0)], axis=1).reshape(-1)

    def force(self, K, e, ed, z, P):
        Z = z.reshape(-1, 3)
        return P.T @ Z[:, 1]

    def state_rate(self, K, e, ed, z, P):
        Z = z.reshape(-1, 3)
        u, F, s = Z[:, 0], Z[:, 1], Z[:, 2]
        v = P @ ed
        rev = (u * v < 0).astype(v.dtype)
        lam = self.reversal_rate
        kt = 2.0 * self.h0 * self.delta**2 / (self.delta + jnp.abs(u) / s) ** 3
        du = v - lam * u * rev
        dF = kt * v
        ds = lam * (2.0 - s) * rev
        return jnp.stack([du, dF, ds], axis=1).reshape(-1)

    def frequency_term(self, K, omega, P):
        return 1j * self.eta * jnp.sign(omega) * K
