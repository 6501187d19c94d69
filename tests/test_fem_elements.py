"""Beam and bar elements and their assembly, against closed forms and hand calculations."""

import numpy as np
import pytest

import jflex
from jflex import fem

_TOL = 1e-10
E, RHO, B, H, L = 2.1e11, 7850.0, 0.02, 0.01, 1.0
AREA, INERTIA = B * H, B * H**3 / 12


def _cantilever(n, angle=0.0):
    nd = [(-1, -1, -1)] + [(3 * k, 3 * k + 1, 3 * k + 2) for k in range(n)]
    model = fem.fe_model(nd, [(k, k + 1, E, AREA, INERTIA, RHO) for k in range(n)])
    s = np.linspace(0, L, n + 1)
    X = np.stack([s * np.cos(angle), s * np.sin(angle)], 1)
    return model, X


def test_cantilever_frequencies_converge_to_euler_bernoulli():
    exact = np.array([1.87510407, 4.69409113, 7.85475744])
    errs = []
    for n in (2, 4, 8, 16):
        model, X = _cantilever(n)
        M, K = model.matrices(X)
        w = np.asarray(fem.modes(M, K).omega)
        # The section is slender enough that the first axial mode lies far above the third bending one.
        beta = np.sqrt(w[:3] * np.sqrt(RHO * AREA * L**4 / (E * INERTIA)))
        errs.append(np.max(np.abs(beta - exact) / exact))
    assert errs[-1] < 5e-5
    # Hermite elements: eigenvalue error O(h^4), so halving h divides it by about 16.
    assert all(a / b > 10 for a, b in zip(errs, errs[1:]))


@pytest.mark.parametrize("angle", [0.0, 0.5236, -2.0])
def test_cantilever_tip_load_deflection(angle):
    P = 1000.0
    model, X = _cantilever(5, angle)
    M, K = model.matrices(X)
    c, s = np.cos(angle), np.sin(angle)
    F = np.zeros(model.n_dof)
    F[-3:-1] = P * np.array([-s, c]) + 3 * P * np.array([c, s])  # transverse P and axial 3P
    U = np.linalg.solve(np.asarray(K), F)
    tip = U[-3:-1]
    np.testing.assert_allclose(tip @ np.array([-s, c]), P * L**3 / (3 * E * INERTIA), rtol=_TOL)
    np.testing.assert_allclose(tip @ np.array([c, s]), 3 * P * L / (E * AREA), rtol=_TOL)
    np.testing.assert_allclose(U[-1], P * L**2 / (2 * E * INERTIA), rtol=_TOL)


def test_bar_element_by_hand():
    Eb, A, Lb, rho, a = 1.68e11, 9e-4, 0.14, 7000.0, np.deg2rad(30.0)
    K, M = fem.bar_matrices(Eb, A, Lb, rho, a)
    k = Eb * A / Lb
    c, s = np.sqrt(3) / 2, 0.5
    blk = k * np.array([[c * c, c * s], [c * s, s * s]])
    np.testing.assert_allclose(K, np.block([[blk, -blk], [-blk, blk]]), rtol=_TOL, atol=1e-3)
    m = rho * A * Lb
    I2 = np.eye(2)
    np.testing.assert_allclose(M, np.block([[m / 3 * I2, m / 6 * I2], [m / 6 * I2, m / 3 * I2]]), rtol=_TOL)
    # rigid translation: no force; total mass m in each direction
    np.testing.assert_allclose(np.asarray(K) @ np.array([1.0, 2.0, 1.0, 2.0]), 0.0, atol=1e-3)
    assert np.isclose(np.asarray(M)[::2, ::2].sum(), m)
    assert np.allclose(fem.bimodular_modulus(np.array([-1.0, 0.0, 2.0]), 1.0, 3.0), [3.0, 1.0, 1.0])


def test_two_element_frame_by_hand():
    # L-frame: clamped at (0,0), element 1 along +x to (L1,0), element 2 along +y to (L1,L2).
    L1, L2 = 2.0, 1.5
    E1, A1, I1 = 2.0e11, 1e-3, 2e-6
    E2, A2, I2 = 1.0e11, 3e-3, 5e-6
    model = fem.fe_model(
        [(-1, -1, -1), (0, 1, 2), (3, 4, 5)],
        [(0, 1, E1, A1, I1, 1.0), (1, 2, E2, A2, I2, 1.0)],
    )
    _, K = model.matrices(np.array([[0.0, 0.0], [L1, 0.0], [L1, L2]]))
    a1, b1 = E1 * A1 / L1, E1 * I1 / L1**3
    a2, b2 = E2 * A2 / L2, E2 * I2 / L2**3
    # element 1 (node j block, axis = global x)
    K1 = np.array([[a1, 0, 0], [0, 12 * b1, -6 * L1 * b1], [0, -6 * L1 * b1, 4 * L1**2 * b1]])
    # element 2 along +y: local u = uy, local v = -ux
    Kii = np.array([[12 * b2, 0, -6 * L2 * b2], [0, a2, 0], [-6 * L2 * b2, 0, 4 * L2**2 * b2]])
    Kij = np.array([[-12 * b2, 0, -6 * L2 * b2], [0, -a2, 0], [6 * L2 * b2, 0, 2 * L2**2 * b2]])
    Kjj = np.array([[12 * b2, 0, 6 * L2 * b2], [0, a2, 0], [6 * L2 * b2, 0, 4 * L2**2 * b2]])
    hand = np.block([[K1 + Kii, Kij], [Kij.T, Kjj]])
    np.testing.assert_allclose(K, hand, rtol=1e-12, atol=1e-6)


def test_pin_shares_translations_only():
    # Two cantilevers meeting at a pin: the pin carries force but no moment.
    P = 500.0
    model = fem.fe_model(
        [(-1, -1, -1), (0, 1, 2), (0, 1, 3), (-1, -1, -1)],
        [(0, 1, E, AREA, INERTIA, RHO), (3, 2, E, AREA, INERTIA, RHO)],
    )
    _, K = model.matrices(np.array([[0.0, 0.0], [L, 0.0], [L, 0.0], [2 * L, 0.0]]))
    U = np.linalg.solve(np.asarray(K), np.array([0.0, P, 0.0, 0.0]))
    # two cantilevers in parallel under the pin's shear
    np.testing.assert_allclose(U[1], P / 2 * L**3 / (3 * E * INERTIA), rtol=_TOL)
    np.testing.assert_allclose(U[2], -U[3], rtol=_TOL)


def test_lumped_mass_and_gather():
    model = fem.fe_model([(-1, -1, -1), (0, 1, 2)], [(0, 1, E, AREA, INERTIA, 0.0)], masses=[(1, 3.0, 0.2)])
    M, _ = model.matrices(np.array([[0.0, 0.0], [1.0, 0.0]]))
    np.testing.assert_allclose(M, np.diag([3.0, 3.0, 0.2]))
    np.testing.assert_allclose(model.gather(np.array([[9.0, 9.0, 9.0], [1.0, 2.0, 3.0]])), [1.0, 2.0, 3.0])
    np.testing.assert_allclose(model.scatter(np.array([1.0, 2.0, 3.0])), [[0, 0, 0], [1, 2, 3]])


def test_bad_parameters_name_the_field():
    with pytest.raises(jflex.ParameterError, match="beam E"):
        fem.fe_model([(-1, -1, -1), (0, 1, 2)], [(0, 1, -1.0, AREA, INERTIA, RHO)])
    with pytest.raises(jflex.ParameterError, match="bar L"):
        fem.fe_model([(-1, -1, -1), (0, 1, 2)], bars=[(0, 1, E, AREA, 0.0, 0.0)])
    with pytest.raises(jflex.ShapeError, match="beams"):
        fem.fe_model([(-1, -1, -1), (0, 1, 2)], [(0, 0, E, AREA, INERTIA, RHO)])


def test_rayleigh_and_modal_damping_ratios():
    model, X = _cantilever(6)
    M, K = model.matrices(X)
    md = fem.modes(M, K)
    w = np.asarray(md.omega)
    al, be = fem.rayleigh_coefficients(w[0], w[2], 0.05, 0.05)
    C = fem.rayleigh_damping(M, K, al, be)
    zeta = np.diag(np.asarray(md.Phi.T @ C @ md.Phi)) / (2 * w)
    np.testing.assert_allclose(zeta[[0, 2]], 0.05, rtol=1e-8)
    Cm = fem.modal_damping(M, K, 0.03)
    Cd = np.asarray(md.Phi.T @ Cm @ md.Phi)
    np.testing.assert_allclose(Cd, np.diag(2 * 0.03 * w), rtol=1e-6, atol=1e-6 * w.max())
