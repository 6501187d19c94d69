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
