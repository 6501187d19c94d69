"""Hysteretic damping (Eqs. 16-27 of
"Numerical Implementation and Comparison Between the Viscous, Fractional and Hysteretic Damping Models of a Rigid-Flexible Planar Manipulator").

In frequency: the complex stiffness ``K (1 + i eta sign(omega))`` (Eq. 22). In time: a
Masing-rule element (Eqs. 25-27) with the virgin curve ``y(x) = h0 [1 - (delta/(delta + x))^2]``:
on the virgin curve ``F = f(x)`` (odd extension of ``y``); after a reversal at ``(x_m, F_m)``,
``F = F_m + 2 f((x - x_m)/2)``. The reversal memory is kept as three states per element: the
travel since the last reversal ``u``, the force ``F`` and the branch factor ``s`` (1 on the virgin
curve, 2 after the first reversal), integrated as ``dF/dt = y'(|u|/s) dx/dt``. A reversal
(``u dx/dt < 0``) resets ``u`` to 0 at the rate ``reversal_rate`` [1/s] (large: a stiff but
continuous stand-in for the jump), and ``s`` relaxes to 2.

Travel-driven reversal (``reversal_width`` [m] given): the reset runs at the rate ``|dx/dt| / width``
instead, i.e. ``u`` decays by ``exp(-travel / width)`` over the reverse travel, independent of time,
as a rate-independent hysteresis should. Why: with the time-driven reset a reversal that travels
back a nanometre for a millisecond (a higher mode's ripple on a slow swing) resets ``u`` fully, so
the force, and every response after it, jumps as a parameter moves the ripple across zero; an
output-error cost is then discontinuous (that paper: factors 2-10 between neighbouring ``delta``).
With the travel-driven reset the right-hand side is Lipschitz in the states (the reset term
``|v| u / width`` vanishes at ``v = 0`` and at ``u = 0``), a reversal of travel ``a`` changes ``u`` by
a fraction ``~ a / width``, and the response is a continuous function of ``h0`` and ``delta``.
As ``width -> 0`` the element tends to the Masing rule: the force lags the explicit rule by about
``y'(0) width = 2 h0 width / delta`` after each reversal (tested against :func:`masing_force`).
The re-joining of the virgin curve
beyond the previous maximum amplitude (the last sentence of the rule after Eq. 26) is not modelled:
in a decaying free vibration the amplitude never exceeds it.
"""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
import numpy as np

from .._errors import ParameterError
from ._damping import AbstractDampingLaw
from ._registry import HYSTERETIC_DAMPING


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
    (virgin curve Eq. 27, time domain); ``reversal_rate`` [1/s] of the time-driven memory reset
    (default 1e4); ``reversal_width`` [m] (default None): if given, the reset is driven by the
    reverse travel instead (``u`` decays as ``exp(-travel / reversal_width)``; ``reversal_rate`` is
    then unused), which makes the response continuous in the parameters (see the module docstring).
    The element acts on ``P e`` (the owner's projection, e.g. a beam's tip deflection).
    """

    eta: jnp.ndarray
    h0: jnp.ndarray
    delta: jnp.ndarray
    reversal_rate: jnp.ndarray
    reversal_width: jnp.ndarray | None
    loss: ClassVar[str] = "eta"
    candidate: ClassVar[str] = HYSTERETIC_DAMPING
    signature: ClassVar[str] = "damping ratio flat in frequency"

    @classmethod
    def prototypes(cls) -> tuple:
        return (cls(eta=1.0),)

    def __init__(self, eta=0.0, h0=0.0, delta=1e-3, reversal_rate=1e4, reversal_width=None):
        for k, v in {"eta": eta, "h0": h0}.items():
            if not np.isfinite(v) or float(v) < 0:
                raise ParameterError(f"Hysteretic.{k} must be >= 0, got {v}")
        pos = {"delta": delta, "reversal_rate": reversal_rate}
        if reversal_width is not None:
            pos["reversal_width"] = reversal_width
        for k, v in pos.items():
            if not np.isfinite(v) or not float(v) > 0:
                raise ParameterError(f"Hysteretic.{k} must be > 0 [{'m' if k != 'reversal_rate' else '1/s'}], got {v}")
        self.eta, self.h0 = jnp.asarray(float(eta)), jnp.asarray(float(h0))
        self.delta, self.reversal_rate = jnp.asarray(float(delta)), jnp.asarray(float(reversal_rate))
        self.reversal_width = None if reversal_width is None else jnp.asarray(float(reversal_width))

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
        # time-driven: a fixed rate; travel-driven: |v| / width, so the reset depends on how far the
        # motion has gone back, not for how long, and vanishes continuously as v -> 0
        lam = self.reversal_rate if self.reversal_width is None else jnp.abs(v) / self.reversal_width
        kt = 2.0 * self.h0 * self.delta**2 / (self.delta + jnp.abs(u) / s) ** 3
        du = v - lam * u * rev
        dF = kt * v
        ds = lam * (2.0 - s) * rev
        return jnp.stack([du, dF, ds], axis=1).reshape(-1)

    def frequency_term(self, K, omega, P):
        return 1j * self.eta * jnp.sign(omega) * K
