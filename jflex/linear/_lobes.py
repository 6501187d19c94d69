"""Milling stability lobes by the zero-order analysis (the thesis "Posture Dependent Dynamics in Robotic Machining" section 4.8, Eqs. 4.15-4.19;
Altintas & Budak 1995, Altintas "Manufacturing Automation" ch. 4).

Cutting coordinates: x feed, y normal to the feed in the plane of the cut, z tool axis; the
immersion angle phi is measured clockwise from +y (Altintas). A tooth at angle phi with lead
(cutting-edge) angle kappa cuts the chip ``h = u(phi) . (r(t) - r(t - tau))``,
``u = [sin phi sin kappa, cos phi sin kappa, -cos kappa]``, over a chip width ``a / sin kappa``,
and feels tangential/radial/axial forces ``(K_t, K_r, K_a) (a / sin kappa) h``. Averaged over the
cut (ZOA), ``F = N_T / (4 pi) a K_t [alpha0] (1 - e^{-i w tau}) G F`` (Eq. 4.16), with

$$ [\\alpha_0] = \\frac{2}{K_t} \\int_{\\phi_{st}}^{\\phi_{ex}} T(\\phi) k\\, u(\\phi)^T / \\sin\\kappa \\, d\\phi, $$

which for kappa = 90 deg is Altintas' 2-D directional matrix. With ``mu`` an eigenvalue of
``[alpha0] G(i w_c)`` and ``Lambda = -1/mu``: ``a = -2 pi Lambda_R (1 + k^2) / (N_T K_t)``,
``k = Lambda_I / Lambda_R``, ``tau = (pi - 2 atan k + 2 pi j) / w_c``, ``n = 60 / (N_T tau)``
(Eqs. 4.18-4.19).
"""

from __future__ import annotations

import itertools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import ParameterError, ShapeError
from ._common import check_frequencies


def immersion_angles(radial_immersion: float, mode: str = "up"):
    """Start and exit angles [rad] for a radial immersion ratio ``b / D`` in (0, 1].

    Up-milling: ``(0, arccos(1 - 2 b/D))``; down-milling: ``(arccos(2 b/D - 1), pi)``.
    """
    rho = float(radial_immersion)
    if not 0 < rho <= 1:
        raise ParameterError(f"radial_immersion: expected b/D in (0, 1], got {radial_immersion}")
    if mode in ("up", "up-milling"):
        return 0.0, float(np.arccos(1 - 2 * rho))
    if mode in ("down", "down-milling"):
        return float(np.arccos(2 * rho - 1)), float(np.pi)
    raise ParameterError(f"milling mode must be 'up' or 'down', got '{mode}'")


def directional_matrix(Kt, Kr, Ka, lead_angle, phi_start, phi_exit, *, n_quad: int = 64):
    """Average directional matrix [alpha0] (3, 3) of the ZOA (Eq. 4.17), by Gauss-Legendre
    quadrature over the immersion. ``Kt``, ``Kr``, ``Ka`` [Pa]; angles [rad]."""
    x, wq = np.polynomial.legendre.leggauss(n_quad)
    phi = 0.5 * (phi_exit - phi_start) * (jnp.asarray(x) + 1) + phi_start
    wq = 0.5 * (phi_exit - phi_start) * jnp.asarray(wq)
    kap = jnp.asarray(lead_angle, dtype=float)
    sk, ck = jnp.sin(kap), jnp.cos(kap)

    def A(p):
        s, c = jnp.sin(p), jnp.cos(p)
        u = jnp.array([s * sk, c * sk, -ck])
        T = jnp.array([[-c, -s * sk, -s * ck], [s, -c * sk, -c * ck], [0.0 * s, ck, -sk]])
        k = jnp.array([Kt, Kr, Ka], dtype=float)
        return jnp.outer(T @ k, u) / sk

    return 2.0 / Kt * jnp.einsum("q,qij->ij", wq, jax.vmap(A)(phi))


class Lobes(eqx.Module):
    """Stability lobes: for each lobe number j and eigenvalue branch, one point per chatter
    frequency. ``spindle_speed`` [rpm] and ``depth`` [m] are (n_lobes, nf, m); points with
    no positive depth are NaN. ``chatter_frequency`` (nf,) [rad/s]. Along the frequency axis a
    branch is one continuous eigenvalue of ``[alpha0] G`` (tracked, not in the eigensolver's
    order), so consecutive points of a branch are neighbours on one lobe curve."""

    spindle_speed: jnp.ndarray
    depth: jnp.ndarray
    chatter_frequency: jnp.ndarray


def stability_lobes(G, omega, *, n_teeth: int, Kt, Kr=0.0, Ka=0.0, lead_angle=np.pi / 2,
                    phi_start=0.0, phi_exit=np.pi / 2, n_lobes: int = 10) -> Lobes:
    """ZOA stability lobes from a tool FRF in cutting coordinates (the thesis Eqs. 4.16-4.19).

    **Arguments:**

    - ``G``: (nf, 3, 3) receptance [m/N] in cutting coordinates (x feed, y normal, z tool axis),
      or (nf, 2, 2) for the planar x-y case; predicted (:func:`jflex.frf`) or measured.
    - ``omega``: (nf,) chatter frequencies [rad/s] (the FRF grid), increasing, > 0.
    - ``n_teeth`` N_T; ``Kt``, ``Kr``, ``Ka`` cutting force coefficients [Pa];
      ``lead_angle`` kappa [rad] (90 deg: straight end mill); ``phi_start``, ``phi_exit``
      immersion [rad] (see :func:`immersion_angles`); ``n_lobes`` lobes j = 0..n_lobes-1.

    **Returns:** :class:`Lobes`.
    """
    omega = check_frequencies(omega)
    G = jnp.asarray(G)
    nf = omega.shape[0]
    if G.ndim != 3 or G.shape[0] != nf or G.shape[1] != G.shape[2] or G.shape[1] not in (2, 3):
        raise ShapeError(f"stability_lobes: G must be (nf, 3, 3) or (nf, 2, 2) with nf = {nf}, got {G.shape}")
    if int(n_teeth) < 1:
        raise ParameterError(f"stability_lobes: n_teeth must be >= 1, got {n_teeth}")
    coeffs = {}
    for name, v in (("Kt", Kt), ("Kr", Kr), ("Ka", Ka)):
        if isinstance(v, str):
            raise ParameterError(f"stability_lobes: {name} must be a number [Pa], got the string '{v}'")
        coeffs[name] = jnp.asarray(v, dtype=float)
    try:
        if float(coeffs["Kt"]) <= 0:
            raise ParameterError(f"stability_lobes: Kt must be > 0 [Pa], got {Kt}")
    except (TypeError, jax.errors.ConcretizationTypeError):
        pass
    Kt, Kr, Ka = coeffs["Kt"], coeffs["Kr"], coeffs["Ka"]
    d = G.shape[1]
    alpha = directional_matrix(Kt, Kr, Ka, lead_angle, phi_start, phi_exit)[:d, :d]
    mu = _track_branches(jnp.linalg.eigvals(jnp.einsum("ij,fjk->fik", alpha, G)))  # (nf, d)
    small = jnp.abs(mu) < 1e-30
    Lam = -1.0 / jnp.where(small, 1.0, mu)
    LR, LI = Lam.real, Lam.imag
    kap = LI / LR
    a = -2 * jnp.pi * LR * (1 + kap**2) / (n_teeth * Kt)
    eps = jnp.pi - 2 * jnp.arctan(kap)
    j = jnp.arange(n_lobes)[:, None, None]
    tau = (eps[None] + 2 * jnp.pi * j) / omega[None, :, None]
    n = 60.0 / (n_teeth * tau)
    ok = (~small) & (a > 0) & (omega[:, None] > 0)
    a = jnp.where(ok, a, jnp.nan)
    return Lobes(jnp.where(ok[None], n, jnp.nan), jnp.broadcast_to(a[None], n.shape), omega)


def _track_branches(mu):
    """``mu`` (nf, d) with each row reordered to follow the previous one (the permutation with the
    least total distance): the eigensolver returns each frequency's eigenvalues in its own order,
    and a column that jumped between two eigenvalues would join points of two lobe curves."""
    d = mu.shape[1]
    perms = jnp.asarray(list(itertools.permutations(range(d))))  # (d!, d); d <= 3

    def step(prev, row):
        cand = row[perms]  # (d!, d)
        best = cand[jnp.argmin(jnp.sum(jnp.abs(cand - prev[None]), axis=1))]
        return best, best

    _, out = jax.lax.scan(step, mu[0], mu)
    return out


def stability_limit(lobes: Lobes, spindle_speed):
    """Lower envelope of the lobes on a spindle-speed grid [rpm]: the largest stable axial depth
    [m] at each speed (NaN where no lobe curve passes over a grid speed).

    Each lobe curve is followed through its points in chatter-frequency order; every segment
    between two consecutive valid points is interpolated onto the grid speeds it spans (the
    inverse depth linearly in speed: it is linear in Re G for one mode, where the depth runs off
    to infinity at a lobe's steep flank; against Altintas' closed-form 1-DOF lobes this took the
    error at the cusps from 3 % to 0.07 % on a 3000-point FRF), and the minimum is taken over all
    segments of all lobes and branches.

    Why segment by segment: near a pair of close modes, or where the FRF's phase turns back, a
    lobe's speed is not monotone in the chatter frequency: the curve folds (posture_modal's
    TX200 configuration 2: lobe 0 runs up to 1170 rpm, back to 1028 rpm and up again, over depths
    3.5-5.7 mm). Sorting such a curve's points by speed and interpolating, as this function did
    before, threads one line through the three passes of the fold, and the envelope zig-zagged
    between 3.8 and 5.7 mm at 1030-1160 rpm; the stable depth is the lowest pass.
    """
    n = np.asarray(lobes.spindle_speed)
    a = np.asarray(lobes.depth)
    grid = np.asarray(spindle_speed, dtype=float)
    if grid.ndim != 1 or not np.all(np.diff(grid) > 0):
        raise ParameterError("stability_limit: spindle_speed must be a 1-D increasing grid [rpm]")
    # segments between consecutive chatter frequencies of one lobe and branch: (n_lobes, nf-1, m)
    x0, x1, y0, y1 = n[:, :-1], n[:, 1:], a[:, :-1], a[:, 1:]
    ok = np.isfinite(x0) & np.isfinite(x1) & np.isfinite(y0) & np.isfinite(y1)
    x0, x1, y0, y1 = x0[ok], x1[ok], y0[ok], y1[ok]
    lo_x, hi_x = np.minimum(x0, x1), np.maximum(x0, x1)
    lo = np.searchsorted(grid, lo_x, side="left")  # the grid speeds inside [lo_x, hi_x]
    hi = np.searchsorted(grid, hi_x, side="right")
    count = np.maximum(hi - lo, 0)
    env = np.full(grid.shape, np.inf)
    if count.sum():
        seg = np.repeat(np.arange(count.size), count)
        idx = np.arange(seg.size) - np.repeat(np.cumsum(count) - count, count) + lo[seg]
        dx = x1[seg] - x0[seg]
        t = np.where(dx != 0, (grid[idx] - x0[seg]) / np.where(dx != 0, dx, 1.0), 0.0)
        # the inverse depth is interpolated: it is linear in Re G for one mode (a = -1 / (2 K_s Re G))
        # and stays smooth where the depth itself runs off to infinity at a lobe's steep flank
        r0, r1 = 1.0 / y0[seg], 1.0 / y1[seg]
        vals = 1.0 / np.where(dx != 0, r0 + t * (r1 - r0), np.maximum(r0, r1))
        np.minimum.at(env, idx, vals)
    env[~np.isfinite(env)] = np.nan
    return env
