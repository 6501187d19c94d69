"""Fractional Voigt-Kelvin damping ``F = k_e K D^alpha e`` (Eqs. 4-15 of
"Numerical Implementation and Comparison Between the Viscous, Fractional and Hysteretic Damping Models of a Rigid-Flexible Planar Manipulator").

In time, ``D^alpha`` (Riemann-Liouville, zero history) is replaced by Oustaloup's rational
approximation of ``s^alpha`` over a stated band ``[w_lo, w_hi]`` with ``2N+1`` poles,

$$ s^\\alpha \\approx G(s) = w_{hi}^\\alpha \\prod_{k=-N}^{N} \\frac{s + w'_k}{s + w_k},\\quad
w'_k = w_{lo} r^{(k+N+(1-\\alpha)/2)/(2N+1)},\\ w_k = w_{lo} r^{(k+N+(1+\\alpha)/2)/(2N+1)},\\ r = w_{hi}/w_{lo}, $$

(Oustaloup 1995; Valerio's toolbox, reference [3] of that paper), realised as ``2N+1`` first-order
states per coordinate: ``G(s) = D + sum_k r_k / (s + w_k)``. In frequency the exact
``(i omega)^alpha`` is used. :func:`grunwald_letnikov` is the independent time-domain reference.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import ParameterError
from ._damping import AbstractDampingLaw
from ._registry import FRACTIONAL_DAMPING


def oustaloup(alpha, w_lo, w_hi, order: int):
    """Zeros, poles (positive numbers [rad/s], (2N+1,) each) and gain of Oustaloup's
    approximation ``G(s) = gain prod (s + zeros) / (s + poles)`` of ``s^alpha``."""
    k = jnp.arange(-order, order + 1)
    r = w_hi / w_lo
    n = 2 * order + 1
    zeros = w_lo * r ** ((k + order + 0.5 * (1 - alpha)) / n)
    poles = w_lo * r ** ((k + order + 0.5 * (1 + alpha)) / n)
    return zeros, poles, w_hi**alpha


def oustaloup_response(alpha, w_lo, w_hi, order: int, omega):
    """``G(i omega)`` of the approximation (complex, same shape as ``omega``)."""
    z, p, g = oustaloup(alpha, w_lo, w_hi, order)
    s = 1j * jnp.asarray(omega)[..., None]
    return g * jnp.prod((s + z) / (s + p), axis=-1)


def _partial_fractions(alpha, w_lo, w_hi, order):
    z, p, g = oustaloup(alpha, w_lo, w_hi, order)
    diff = p[None, :] - p[:, None]  # p_j - p_k
    diff = jnp.where(jnp.eye(p.shape[0], dtype=bool), 1.0, diff)
    res = g * jnp.prod(z[None, :] - p[:, None], axis=1) / jnp.prod(diff, axis=1)
    return g, p, res


def grunwald_letnikov(f, h: float, alpha: float) -> np.ndarray:
    """Grunwald-Letnikov derivative of order ``alpha`` of samples ``f`` (N,) at step ``h`` [s],
    zero history before ``f[0]``: ``h^-alpha sum_j w_j f[n-j]``, ``w_j = w_{j-1} (1 - (alpha+1)/j)``."""
    f = np.asarray(f, dtype=float)
    n = f.size
    w = np.empty(n)
    w[0] = 1.0
    for j in range(1, n):
        w[j] = w[j - 1] * (1.0 - (alpha + 1.0) / j)
    return np.array([w[: i + 1] @ f[i::-1] for i in range(n)]) / h**alpha


class Fractional(AbstractDampingLaw):
    """Fractional Voigt-Kelvin damping ``F = k_e K D^alpha e``.

    **Arguments:** ``k_e`` [s^alpha]; ``alpha`` in (0, 1]; ``band`` ``(w_lo, w_hi)`` [rad/s] over
    which the time-domain approximation holds (outside it ``G`` flattens to constants); ``order``
    N (static): ``2N+1`` states per coordinate. With ``order`` = 2 per decade the gain error
    inside the band is below about 1 % and the phase error below about 1 degree.
    """

    k_e: jnp.ndarray
    alpha: jnp.ndarray
    w_lo: jnp.ndarray
    w_hi: jnp.ndarray
    order: int = eqx.field(static=True)
    loss: ClassVar[str] = "k_e"
    candidate: ClassVar[str] = FRACTIONAL_DAMPING
    shape: ClassVar[tuple] = ("alpha", 0.1, 0.95)
    signature: ClassVar[str] = "damping ratio growing as w^(alpha-1)"

    @classmethod
    def prototypes(cls) -> tuple:
        return tuple(cls(1.0, a) for a in (0.25, 0.5, 0.75))

    def __init__(self, k_e, alpha, band=(1e-2, 1e4), order: int = 6):
        if not np.isfinite(k_e) or float(k_e) < 0:
            raise ParameterError(f"Fractional.k_e must be >= 0, got {k_e}")
        if not 0.0 < float(alpha) <= 1.0:
            raise ParameterError(f"Fractional.alpha must lie in (0, 1], got {alpha}")
        lo, hi = (float(b) for b in band)
        if not 0 < lo < hi:
            raise ParameterError(f"Fractional.band must be (w_lo, w_hi) with 0 < w_lo < w_hi [rad/s], got {band}")
        if int(order) < 1:
            raise ParameterError(f"Fractional.order must be >= 1, got {order}")
        self.k_e, self.alpha = jnp.asarray(float(k_e)), jnp.asarray(float(alpha))
        self.w_lo, self.w_hi, self.order = jnp.asarray(lo), jnp.asarray(hi), int(order)

    def state_suffixes(self, m, r):
        return tuple(f"frac{i}_{k}" for i in range(m) for k in range(2 * self.order + 1))

    def derivative(self, e, z):
        """``D^alpha e`` (m,) from the filter states ``z`` (m * (2N+1),)."""
        g, p, res = _partial_fractions(self.alpha, self.w_lo, self.w_hi, self.order)
        Z = z.reshape(e.shape[0], p.shape[0])
        return g * e + Z @ res

    def force(self, K, e, ed, z, P):
        return self.k_e * (K @ self.derivative(e, z))

    def state_rate(self, K, e, ed, z, P):
        _, p, _ = _partial_fractions(self.alpha, self.w_lo, self.w_hi, self.order)
        Z = z.reshape(e.shape[0], p.shape[0])
        return (-Z * p[None, :] + e[:, None]).reshape(-1)

    def frequency_term(self, K, omega, P):
        g, _, _ = _partial_fractions(self.alpha, self.w_lo, self.w_hi, self.order)
        # the linearisation with frozen states already holds k_e K g (the feedthrough)
        exact = (1j * omega + 0j) ** self.alpha
        return self.k_e * K * (exact - g)
