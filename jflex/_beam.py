"""Euler-Bernoulli / Rayleigh beams for assumed-mode links: mode shapes and quadrature.

Mode shapes are those of a clamped beam, free or carrying a tip mass (with rotary inertia) at
``xi = s / L = 1``,

$$ \\phi(\\xi) = c\\,[\\cosh \\beta\\xi - \\cos \\beta\\xi - \\sigma (\\sinh \\beta\\xi - \\sin \\beta\\xi)], $$

with ``beta`` the roots of the characteristic equation and ``c`` scaling each shape to unit tip
deflection, so a modal coordinate is the tip deflection [m] that mode contributes. Integrals
over the beam use Gauss-Legendre quadrature with a static number of points.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._errors import ParameterError

CLAMPED_FREE = "clamped-free"
TIP_MASS = "tip-mass"


def _char_det(b, mu, j):
    """Characteristic determinant of a clamped beam with tip mass ratio ``mu`` = M/(m L) and tip
    rotary inertia ratio ``j`` = J/(m L^3), scaled by 1/cosh^2 so it stays O(1).

    From the natural boundary conditions at the tip, phi'' = j b^4 phi', phi''' = -mu b^4 phi
    (derived from the Lagrangian; for j = 0 it reduces to the published
    1 + cos cosh + mu b (cos sinh - sin cosh) = 0)."""
    ch, sh, c, s = np.cosh(b), np.sinh(b), np.cos(b), np.sin(b)
    a11 = (ch + c) - j * b**3 * (sh + s)
    a12 = (sh + s) - j * b**3 * (ch - c)
    a21 = (sh - s) + mu * b * (ch - c)
    a22 = (ch + c) + mu * b * (sh - s)
    return (a11 * a22 - a12 * a21) / ch**2


def beam_roots(n_modes: int, mass_ratio: float = 0.0, inertia_ratio: float = 0.0) -> np.ndarray:
    """First ``n_modes`` roots ``beta L`` of a clamped beam's characteristic equation.

    **Arguments:** ``mass_ratio`` tip mass / beam mass (0: clamped-free, roots 1.8751, 4.6941,
    7.8548, ...); ``inertia_ratio`` tip rotary inertia / (beam mass L^2).

    **Returns:** (n_modes,) array.
    """
    if n_modes < 1:
        raise ParameterError(f"n_modes must be >= 1, got {n_modes}")
    if mass_ratio < 0 or inertia_ratio < 0:
        raise ParameterError(f"tip mass ratio and inertia ratio must be >= 0, got {mass_ratio}, {inertia_ratio}")
    from scipy.optimize import brentq  # here, not at import: scipy.optimize costs ~0.3 s to load

    f = lambda b: _char_det(b, mass_ratio, inertia_ratio)
    roots = []
    grid = np.linspace(1e-3, (n_modes + 2) * np.pi, 4000 * (n_modes + 2))
    vals = f(grid)
    for k in range(len(grid) - 1):
        if np.sign(vals[k]) != np.sign(vals[k + 1]):
            roots.append(brentq(f, grid[k], grid[k + 1], xtol=1e-14, rtol=1e-14))
            if len(roots) == n_modes:
                break
    if len(roots) < n_modes:
        raise ParameterError(f"beam_roots: found only {len(roots)} of {n_modes} roots")
    return np.array(roots)


def _sigma(b, j):
    ch, sh, c, s = np.cosh(b), np.sinh(b), np.cos(b), np.sin(b)
    return ((ch + c) - j * b**3 * (sh + s)) / ((sh + s) - j * b**3 * (ch - c))


def _raw_shapes(beta, sigma, xi):
    """phi, phi', phi'', phi''' (derivatives in xi) of the unscaled shapes; (m,) each for scalar xi.

    Written with exponentials so the cancellation cosh - sigma sinh stays accurate for high modes."""
    bx = beta * xi
    ep, em = jnp.exp(bx - beta), jnp.exp(-bx)  # e^{bx} scaled by e^{-beta}
    scale = jnp.exp(beta)
    # cosh - sigma sinh = ((1 - sigma) e^{bx} + (1 + sigma) e^{-bx}) / 2
    hyp0 = 0.5 * ((1 - sigma) * ep * scale + (1 + sigma) * em)
    hyp1 = 0.5 * ((1 - sigma) * ep * scale - (1 + sigma) * em)  # sinh - sigma cosh
    c, s = jnp.cos(bx), jnp.sin(bx)
    phi = hyp0 - c + sigma * s
    d1 = beta * (hyp1 + s + sigma * c)
    d2 = beta**2 * (hyp0 + c - sigma * s)
    d3 = beta**3 * (hyp1 - s - sigma * c)
    return phi, d1, d2, d3


class Beam(eqx.Module):
    """A uniform beam clamped at ``s = 0``, planar bending, with its assumed-mode basis.

    **Fields:** ``length`` L [m] (nominal; a sliding link scales the shapes with its current
    length); ``mass_per_length`` rho A [kg/m]; ``EI`` [N m^2]; ``rotary_inertia`` rho I [kg m]
    (0: Euler-Bernoulli, > 0: Rayleigh beam); ``tip_mass`` [kg]; ``tip_inertia`` [kg m^2] about
    the bending axis; ``beta`` (m,), ``sigma`` (m,), ``scale`` (m,) the basis (not physical
    parameters: any admissible basis gives a valid Ritz model); ``n_modes``, ``boundary``,
    ``n_quad`` static.
    """

    length: jnp.ndarray
    mass_per_length: jnp.ndarray
    EI: jnp.ndarray
    rotary_inertia: jnp.ndarray
    tip_mass: jnp.ndarray
    tip_inertia: jnp.ndarray
    beta: jnp.ndarray
    sigma: jnp.ndarray
    scale: jnp.ndarray
    n_modes: int = eqx.field(static=True)
    boundary: str = eqx.field(static=True)
    n_quad: int = eqx.field(static=True)

    def shapes(self, xi):
        """``(phi, phi', phi'')``, derivatives with respect to xi = s / L: (m,) each at a scalar
        ``xi``, (..., m) for an array of stations."""
        p, d1, d2, _ = _raw_shapes(self.beta, self.sigma, jnp.asarray(xi)[..., None])
        return p * self.scale, d1 * self.scale, d2 * self.scale

    def quadrature(self):
        """Gauss-Legendre nodes and weights on [0, 1], (n_quad,) each (static numpy)."""
        x, w = np.polynomial.legendre.leggauss(self.n_quad)
        return 0.5 * (x + 1.0), 0.5 * w


def make_beam(
    length,
    mass_per_length,
    EI,
    n_modes: int,
    *,
    rotary_inertia=0.0,
    tip_mass=0.0,
    tip_inertia=0.0,
    boundary: str | None = None,
    n_quad: int | None = None,
) -> Beam:
    """Build a :class:`Beam`, validating every parameter (named :class:`jflex.ParameterError`).

    ``boundary``: ``"clamped-free"`` (shapes of a free tip, the default without a tip mass) or
    ``"tip-mass"`` (shapes solving the tip-mass characteristic equation, default with one).
    """
    vals = {"length": length, "mass_per_length": mass_per_length, "EI": EI}
    for k, v in vals.items():
        if not np.isfinite(v) or not float(v) > 0:
            raise ParameterError(f"Beam.{k} must be a finite number > 0, got {v}")
    for k, v in {"rotary_inertia": rotary_inertia, "tip_mass": tip_mass, "tip_inertia": tip_inertia}.items():
        if not np.isfinite(v) or float(v) < 0:
            raise ParameterError(f"Beam.{k} must be a finite number >= 0, got {v}")
    if int(n_modes) < 1:
        raise ParameterError(f"Beam.n_modes must be >= 1, got {n_modes}")
    if boundary is None:
        boundary = TIP_MASS if (float(tip_mass) > 0 or float(tip_inertia) > 0) else CLAMPED_FREE
    if boundary not in (CLAMPED_FREE, TIP_MASS):
        raise ParameterError(f"Beam.boundary must be '{CLAMPED_FREE}' or '{TIP_MASS}', got '{boundary}'")
    mL = float(mass_per_length) * float(length)
    mu = float(tip_mass) / mL if boundary == TIP_MASS else 0.0
    j = float(tip_inertia) / (mL * float(length) ** 2) if boundary == TIP_MASS else 0.0
    beta = beam_roots(int(n_modes), mu, j)
    sigma = _sigma(beta, j)
    p, *_ = _raw_shapes(jnp.asarray(beta), jnp.asarray(sigma), 1.0)
    scale = 1.0 / np.asarray(p)
    nq = n_quad if n_quad is not None else max(16, 4 * int(n_modes) + 12)
    f = lambda v: jnp.asarray(float(v))
    return Beam(
        length=f(length), mass_per_length=f(mass_per_length), EI=f(EI), rotary_inertia=f(rotary_inertia),
        tip_mass=f(tip_mass), tip_inertia=f(tip_inertia), beta=jnp.asarray(beta), sigma=jnp.asarray(sigma),
        scale=jnp.asarray(scale), n_modes=int(n_modes), boundary=boundary, n_quad=int(nq),
    )


def beam_modal_matrices(beam: Beam, length=None):
    """Mass and stiffness matrices (m, m) of the clamped beam alone in its modal coordinates.

    ``M = rho A L int phi phi^T + rho I / L int phi' phi'^T + M_t phi(1) phi(1)^T + J_t/L^2 phi'(1) phi'(1)^T``,
    ``K = EI / L^3 int phi'' phi''^T``, by Gauss quadrature. ``length`` overrides the nominal length.
    """
    L = beam.length if length is None else jnp.asarray(length)
    xs, ws = beam.quadrature()
    p, d1, d2 = beam.shapes(jnp.asarray(xs))
    w = jnp.asarray(ws)[:, None]
    M = beam.mass_per_length * L * p.T @ (w * p) + beam.rotary_inertia / L * d1.T @ (w * d1)
    K = beam.EI / L**3 * d2.T @ (w * d2)
    p1, d11, _ = beam.shapes(1.0)
    M = M + beam.tip_mass * jnp.outer(p1, p1) + beam.tip_inertia / L**2 * jnp.outer(d11, d11)
    return M, K


def clamped_free_frequencies(beam: Beam, n_modes: int | None = None):
    """Closed-form natural frequencies ``(beta L)^2 sqrt(EI / (rho A L^4))`` [rad/s] of an
    Euler-Bernoulli clamped-free beam (no tip mass, no rotary inertia)."""
    b = beam_roots(n_modes or beam.n_modes)
    return jnp.asarray(b) ** 2 * jnp.sqrt(beam.EI / (beam.mass_per_length * beam.length**4))
