"""Beam mode shapes and assumed-mode matrices against closed forms and an FE reference."""

import numpy as np
import pytest
import scipy.linalg as sl

import jflex
from _references import fe_beam_matrices

REL = 1e-3  # the 0.1 %


def _fe_frequencies(L, m, EI, Mt=0.0, Jt=0.0, ne=60, k=4):
    """Independent reference: Hermite cubic finite elements of a clamped beam with a tip body."""
    K, M = fe_beam_matrices(L, m, EI, ne)
    M[-2, -2] += Mt
    M[-1, -1] += Jt
    w2 = sl.eigh(K[2:, 2:], M[2:, 2:], eigvals_only=True)[:k]
    return np.sqrt(w2)


def test_clamped_free_roots_and_frequencies():
    b = jflex.beam_roots(3)
    np.testing.assert_allclose(b, [1.8751, 4.6941, 7.8548], rtol=REL)
    beam = jflex.make_beam(0.9, 0.157, 0.349, 3)
    w = np.asarray(jflex.clamped_free_frequencies(beam))
    np.testing.assert_allclose(w, b**2 * np.sqrt(0.349 / (0.157 * 0.9**4)), rtol=1e-12)
    # the assumed-mode matrices (quadrature) reproduce them
    M, K = jflex.beam_modal_matrices(beam)
    np.testing.assert_allclose(np.sqrt(sl.eigh(np.asarray(K), np.asarray(M), eigvals_only=True)), w, rtol=1e-9)
    np.testing.assert_allclose(w, _fe_frequencies(0.9, 0.157, 0.349, k=3), rtol=REL)


def test_tip_mass_roots_against_published_value_and_fe():
    # Blevins, Formulas for natural frequency and mode shape, Table 8-8: M / (m L) = 1 -> 1.2479
    assert abs(jflex.beam_roots(1, 1.0)[0] - 1.2479) < 1e-4
    for mu, j in [(0.5, 0.0), (2.0, 0.0), (1.0, 0.05)]:
        L, m, EI = 0.8, 0.3, 2.0
        b = jflex.beam_roots(3, mu, j)
        w = b**2 * np.sqrt(EI / (m * L**4))
        np.testing.assert_allclose(w, _fe_frequencies(L, m, EI, mu * m * L, j * m * L**3, k=3), rtol=REL)
        beam = jflex.make_beam(L, m, EI, 3, tip_mass=mu * m * L, tip_inertia=j * m * L**3)
        M, K = jflex.beam_modal_matrices(beam)
        np.testing.assert_allclose(np.sqrt(sl.eigh(np.asarray(K), np.asarray(M), eigvals_only=True)), w, rtol=1e-8)


def test_assumed_modes_converge_from_above():
    """Clamped-free shapes as a Ritz basis for a beam with a tip mass: frequencies decrease
    monotonically towards the exact ones as modes are added (Rayleigh-Ritz bound)."""
    L, m, EI, Mt = 1.0, 0.2, 1.5, 0.1
    exact = _fe_frequencies(L, m, EI, Mt, k=2)
    prev = None
    errs = []
    for n in (2, 3, 5, 8):
        beam = jflex.make_beam(L, m, EI, n, tip_mass=Mt, boundary="clamped-free", n_quad=60)
        M, K = jflex.beam_modal_matrices(beam)
        w = np.sqrt(sl.eigh(np.asarray(K), np.asarray(M), eigvals_only=True))[:2]
        assert np.all(w >= exact * (1 - 1e-9))
        if prev is not None:
            assert np.all(w <= prev + 1e-12)
        prev = w
        errs.append(np.max(w / exact - 1))
    assert errs[-1] < 1e-3 and errs[-1] < errs[0]


def test_rayleigh_beam_rotary_inertia_lowers_frequencies():
    """Rotary inertia (Rayleigh beam) lowers the frequencies by about (1 + (beta r)^2 ...) : check
    against FE with rotary inertia in a consistent mass matrix is beyond this reference, so check
    the first-order estimate w_R / w_EB ~ 1 - (beta_n r)^2 / 2 * c_n for a slender beam."""
    L, m, EI = 1.0, 0.2, 1.5
    r2 = 1e-5  # radius of gyration squared [m^2]
    eb = jflex.make_beam(L, m, EI, 3, n_quad=60)
    rb = jflex.make_beam(L, m, EI, 3, rotary_inertia=m * r2, n_quad=60)
    f = lambda b: np.sqrt(sl.eigh(*[np.asarray(a) for a in reversed(jflex.beam_modal_matrices(b))], eigvals_only=True))
    w_eb, w_r = f(eb), f(rb)
    assert np.all(w_r < w_eb)
    # Rayleigh quotient with the EB shape: w_R^2 = K / (M + rho I int phi'^2 / L)
    M, K = (np.asarray(a) for a in jflex.beam_modal_matrices(eb))
    Mr, _ = (np.asarray(a) for a in jflex.beam_modal_matrices(rb))
    np.testing.assert_allclose(w_r[0], np.sqrt(K[0, 0] / Mr[0, 0]), rtol=1e-6)


def test_bad_beam_parameters_raise():
    with pytest.raises(jflex.ParameterError, match="EI"):
        jflex.make_beam(1.0, 1.0, -1.0, 2)
    with pytest.raises(jflex.ParameterError, match="n_modes"):
        jflex.make_beam(1.0, 1.0, 1.0, 0)
