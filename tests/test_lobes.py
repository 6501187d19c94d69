"""ZOA stability lobes (seed 003 Eqs. 4.15-4.19) against Altintas' closed-form directional
coefficients and the characteristic equation they come from."""

import numpy as np
import pytest

import jflex
from jflex.linear import directional_matrix, immersion_angles, stability_limit, stability_lobes


def altintas_2d(Kr, st, ex):
    """Altintas (Manufacturing Automation, Eq. 4.66) 2-D directional coefficients."""
    f = lambda g, p: g(p)
    axx = 0.5 * (np.cos(2 * ex) - 2 * Kr * ex + Kr * np.sin(2 * ex)) - 0.5 * (np.cos(2 * st) - 2 * Kr * st + Kr * np.sin(2 * st))
    axy = 0.5 * (-np.sin(2 * ex) - 2 * ex + Kr * np.cos(2 * ex)) - 0.5 * (-np.sin(2 * st) - 2 * st + Kr * np.cos(2 * st))
    ayx = 0.5 * (-np.sin(2 * ex) + 2 * ex + Kr * np.cos(2 * ex)) - 0.5 * (-np.sin(2 * st) + 2 * st + Kr * np.cos(2 * st))
    ayy = 0.5 * (-np.cos(2 * ex) - 2 * Kr * ex - Kr * np.sin(2 * ex)) - 0.5 * (-np.cos(2 * st) - 2 * Kr * st - Kr * np.sin(2 * st))
    return np.array([[axx, axy], [ayx, ayy]])


@pytest.mark.parametrize("rho,mode", [(0.5, "up"), (0.25, "down"), (1.0, "up")])
def test_directional_matrix_matches_altintas_2d(rho, mode):
    st, ex = immersion_angles(rho, mode)
    A = np.asarray(directional_matrix(600e6, 0.3 * 600e6, 0.0, np.pi / 2, st, ex))
    assert np.allclose(A[:2, :2], altintas_2d(0.3, st, ex), atol=1e-12)
    assert np.allclose(A[2], 0.0, atol=1e-12)


def test_lobe_points_satisfy_the_characteristic_equation():
    # a two-mode tool FRF in cutting axes
    w = 2 * np.pi * np.linspace(5.0, 60.0, 400)
    M, C, K = np.diag([20.0, 30.0, 25.0]), np.diag([300.0, 250.0, 400.0]), np.diag([2e5, 6e5, 9e5])
    G = np.asarray(jflex.linear.frf_matrices(M, C, K, w))
    N, Kt, Kr, Ka, kap = 4, 800e6, 160e6, 40e6, np.radians(40.0)
    st, ex = immersion_angles(0.5, "up")
    lob = stability_lobes(G, w, n_teeth=N, Kt=Kt, Kr=Kr, Ka=Ka, lead_angle=kap, phi_start=st, phi_exit=ex, n_lobes=3)
    alpha = np.asarray(directional_matrix(Kt, Kr, Ka, kap, st, ex))
    n, a = np.asarray(lob.spindle_speed), np.asarray(lob.depth)
    checked = 0
    for j in range(3):
        for f in range(0, 400, 37):
            for b in range(3):
                if not np.isfinite(a[j, f, b]):
                    continue
                tau = 60.0 / (N * n[j, f, b])
                D = np.eye(3) - N / (4 * np.pi) * a[j, f, b] * Kt * (1 - np.exp(-1j * w[f] * tau)) * alpha @ G[f]
                assert abs(np.linalg.det(D)) < 1e-8
                checked += 1
    assert checked > 10
    rpm = np.linspace(50, 2000, 500)
    lim = stability_limit(lob, rpm)
    assert np.nanmin(lim) >= np.nanmin(a) - 1e-15 and np.isfinite(lim).sum() > 100


def test_bad_lobe_inputs():
    w = np.array([1.0, 2.0])
    with pytest.raises(jflex.ShapeError):
        stability_lobes(np.zeros((3, 3, 3)), w, n_teeth=2, Kt=1e8)
    with pytest.raises(jflex.ParameterError):
        stability_lobes(np.zeros((2, 3, 3)), w[::-1], n_teeth=2, Kt=1e8)
    with pytest.raises(jflex.ParameterError):
        immersion_angles(1.5)


# ---- the envelope against the closed-form lobes of a 1-DOF system ---------------------------


def _one_dof(Kr_ratio=0.3):
    """A tool flexible along the feed x only, half-immersion up-milling: the ZOA reduces to
    Altintas' 1-DOF lobes with K_s = -N Kt alpha_xx / (4 pi) (alpha_xx < 0 here)."""
    m, k, zeta = 5.0, 2e7, 0.03
    wn = np.sqrt(k / m)
    N, Kt = 4, 6e8
    st, ex = immersion_angles(0.5, "up")
    axx = altintas_2d(Kr_ratio, st, ex)[0, 0]
    Ks = -N * Kt * axx / (4 * np.pi)
    g = lambda w: 1.0 / (k - m * w**2 + 2j * zeta * np.sqrt(k * m) * w)
    return dict(g=g, wn=wn, N=N, Kt=Kt, Kr=Kr_ratio * Kt, st=st, ex=ex, Ks=Ks)


def closed_form_envelope(s, rpm, n_lobes, w):
    """Altintas' 1-DOF lobes: a_lim = -1/(2 K_s Re G) where Re G < 0, spindle speed
    n = 60 f_c / (N (k + eps / 2 pi)) with eps = 3 pi + 2 psi, psi = arg G in (-pi, 0]
    (= 2 pi - 2 atan(Re G / Im G): the form 3 pi - 2 atan(Re/Im) misses the characteristic
    equation by pi). Each lobe's speed rises with the chatter frequency: plain interpolation."""
    G = s["g"](w)
    neg = G.real < 0
    w, G = w[neg], G[neg]
    a = -1.0 / (2 * s["Ks"] * G.real)
    eps = 3 * np.pi + 2 * np.angle(G)
    env = np.full(rpm.shape, np.inf)
    for j in range(n_lobes):
        n = 60 * w / (2 * np.pi) / (s["N"] * (j + eps / (2 * np.pi)))
        assert np.all(np.diff(n) > 0)
        inside = (rpm >= n[0]) & (rpm <= n[-1])
        env[inside] = np.minimum(env[inside], np.interp(rpm[inside], n, a))
    return np.where(np.isfinite(env), env, np.nan)


def test_closed_form_phase_satisfies_the_characteristic_equation():
    # the reference itself, checked once: 1 - exp(-i eps) = -1 / (K_s a G) on the lobes
    s = _one_dof()
    w = s["wn"] * np.linspace(1.001, 1.8, 50)
    G = s["g"](w)
    a = -1.0 / (2 * s["Ks"] * G.real)
    eps = 3 * np.pi + 2 * np.angle(G)
    assert np.allclose(1 - np.exp(-1j * eps), -1.0 / (s["Ks"] * a * G), rtol=1e-12, atol=1e-12)


def _extrema(y):
    d = np.sign(np.diff(y))
    d = d[d != 0]
    return int(np.sum(d[1:] != d[:-1]))


def test_envelope_matches_closed_form_1dof_lobes_and_is_smooth():
    s = _one_dof()
    n_lobes = 8
    w = s["wn"] * np.linspace(0.5, 2.0, 3000)
    G = np.zeros((w.size, 2, 2), complex)
    G[:, 0, 0] = s["g"](w)
    lob = stability_lobes(G, w, n_teeth=s["N"], Kt=s["Kt"], Kr=s["Kr"], phi_start=s["st"], phi_exit=s["ex"],
                          n_lobes=n_lobes)
    # the lobes of the 4 lowest lobe numbers, where the 8 computed ones set the envelope
    n_all = np.asarray(lob.spindle_speed)
    rpm = np.linspace(np.nanmin(n_all[3]), np.nanmax(n_all[0]), 4000)
    got = stability_limit(lob, rpm)
    ref = closed_form_envelope(s, rpm, n_lobes, s["wn"] * np.linspace(0.5, 2.0, 400_000))
    both = np.isfinite(got) & np.isfinite(ref)
    assert both.mean() > 0.99
    assert np.max(np.abs(got[both] / ref[both] - 1)) < 0.01
    # smooth: as many turns as the closed form (one minimum per lobe, one cusp between lobes);
    # a zig-zag adds a turn at every grid step it crosses
    assert _extrema(got[both]) == _extrema(ref[both]) >= 5
    cusps = np.flatnonzero((got[1:-1] > got[:-2]) & (got[1:-1] > got[2:])) + 1
    for c0, c1 in zip(cusps[:-1], cusps[1:]):  # between cusps: down, then up, on one lobe
        d = np.sign(np.diff(got[c0:c1 + 1]))
        assert np.all(np.diff(d[d != 0]) >= 0)


def test_envelope_of_a_folded_lobe_is_its_lowest_pass():
    # a lobe whose speed turns back with the chatter frequency (close modes; posture_modal's TX200
    # configuration 2 at 1030-1170 rpm): n(t) = 1100 + 100 (t^3 - t), a(t) = 4 + t [mm], t in [-1.5, 1.5]
    t = np.linspace(-1.5, 1.5, 601)
    n, a = 1100 + 100 * (t**3 - t), 1e-3 * (4 + t)
    lob = jflex.linear.Lobes(n[None, :, None], a[None, :, None], np.linspace(1.0, 2.0, t.size))
    rpm = np.linspace(800, 1400, 301)
    got = stability_limit(lob, rpm)
    ref = np.full(rpm.shape, np.nan)
    for i, v in enumerate(rpm):  # every pass of the curve over this speed: the real roots of n(t) = v
        r = np.roots([100, 0, -100, 1100 - v])
        r = r[(np.abs(r.imag) < 1e-9) & (np.abs(r.real) <= 1.5)].real
        if r.size:
            ref[i] = 1e-3 * (4 + r.min())
    assert np.array_equal(np.isfinite(got), np.isfinite(ref))
    assert np.allclose(got[np.isfinite(ref)], ref[np.isfinite(ref)], rtol=1e-3)
    assert _extrema(got[np.isfinite(got)]) == 0  # the lowest pass rises with speed: no zig-zag


def test_branches_are_tracked_across_frequencies():
    from jflex.linear._lobes import _track_branches

    f = np.linspace(0, 1, 200)
    # three eigenvalue paths; two of them pass within 0.1 of each other at f = 0.5
    mu = np.stack([(1 + f) + 1j * f, (2 - f) + 1j * (1.0 - 0.8 * f), 3 + 0.5j + f**2], axis=1)
    rng = np.random.default_rng(1)
    shuffled = np.stack([row[rng.permutation(3)] for row in mu])
    tracked = np.asarray(_track_branches(shuffled))
    order = [int(np.argmin(np.abs(mu[0] - v))) for v in tracked[0]]
    assert np.allclose(tracked, mu[:, order])
