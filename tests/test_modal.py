"""Modal analysis, FRFs and MAC against the closed forms of seed 000 and SciPy references."""

import jax
import numpy as np
import pytest
import scipy.linalg as sla

import jflex
from _references import light_system
from jflex.linear import eigen, frf_matrices, half_power_damping, mac, modes, track_modes

_TOL = 1e-9


def _random_system(n, seed, proportional=False, alpha=0.0, beta=0.0):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    M = A @ A.T + n * np.eye(n)
    B = rng.normal(size=(n, n))
    K = 100.0 * (B @ B.T + n * np.eye(n))
    if proportional:
        C = alpha * M + beta * K
    else:
        D = rng.normal(size=(n, n))
        C = 0.5 * (D @ D.T)
    return M, C, K


@pytest.mark.parametrize("m,c,k", [(2.0, 0.4, 800.0), (1.0, 0.0, 1.0), (5.0, 10.0, 3e4)])
def test_one_dof_closed_forms(m, c, k):
    md = modes(np.array([[m]]), np.array([[c]]), np.array([[k]]))
    w0 = np.sqrt(k / m)
    zeta = c / (2 * np.sqrt(k * m))
    assert np.allclose(md.frequency, w0 / (2 * np.pi), rtol=_TOL)
    assert np.allclose(md.damping_ratio, zeta, atol=_TOL)
    assert np.allclose(md.eigenvalue.imag, w0 * np.sqrt(1 - zeta**2), rtol=_TOL)  # omega_d
    assert np.allclose(md.eigenvalue.real, -zeta * w0, atol=_TOL * w0)
    if c > 0:
        assert np.allclose(md.modal_mass.real, m, rtol=1e-9)


def test_one_dof_resonance_and_kinds():
    m, c, k = 2.0, 3.0, 5e3
    w0, zeta = np.sqrt(k / m), c / (2 * np.sqrt(k * m))
    wr = w0 * np.sqrt(1 - 2 * zeta**2)
    Hr = 1 / (2 * k * zeta * (zeta + 1j * np.sqrt(1 - 2 * zeta**2)))
    w = np.array([0.0, wr * (1 - 1e-3), wr, wr * (1 + 1e-3), 3 * w0])
    M, C, K = np.array([[m]]), np.array([[c]]), np.array([[k]])
    H = np.asarray(frf_matrices(M, C, K, w))[:, 0, 0]
    ref = 1 / (k - m * w**2 + 1j * c * w)
    assert np.allclose(H, ref, rtol=1e-12)
    assert np.allclose(H[2], Hr, rtol=1e-12)
    assert abs(H[2]) > abs(H[1]) and abs(H[2]) > abs(H[3])  # omega_r is the maximum of |H|
    mob = np.asarray(frf_matrices(M, C, K, w, kind="mobility"))[:, 0, 0]
    acc = np.asarray(frf_matrices(M, C, K, w, kind="accelerance", method="modal"))[:, 0, 0]
    assert np.allclose(mob, 1j * w * ref, rtol=1e-12)
    assert np.allclose(acc, -(w**2) * ref, rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize("zeta", [0.005, 0.02, 0.05])
def test_half_power_damping(zeta):
    m, k = 1.0, (2 * np.pi * 10) ** 2
    c = 2 * zeta * np.sqrt(k * m)
    w0 = np.sqrt(k / m)
    w = np.linspace(0.5 * w0, 1.5 * w0, 20001)
    H = 1 / (k - m * w**2 + 1j * c * w)
    est, wpk = half_power_damping(w, H)
    # the half-power rule is exact to first order in zeta
    assert abs(float(est) - zeta) < 2 * zeta**2 + 1e-5
    assert abs(float(wpk) - w0 * np.sqrt(1 - 2 * zeta**2)) < 1e-3 * w0


@pytest.mark.parametrize("n,seed", [(2, 0), (3, 1), (5, 2)])
def test_modal_expansion_equals_direct_inverse(n, seed):
    M, C, K = _random_system(n, seed)
    w = np.linspace(0.0, 60.0, 41)
    Hd = np.asarray(frf_matrices(M, C, K, w, method="direct"))
    Hm = np.asarray(frf_matrices(M, C, K, w, method="modal"))
    ref = np.stack([np.linalg.inv(K - wi**2 * M + 1j * wi * C) for wi in w])
    assert np.allclose(Hd, ref, rtol=1e-9, atol=1e-14)
    assert np.allclose(Hm, ref, rtol=1e-7, atol=1e-12)
    T = np.random.default_rng(seed).normal(size=(2, n))
    HT = np.asarray(frf_matrices(M, C, K, w, T=T, method="modal"))
    assert np.allclose(HT, np.einsum("ij,fjk,lk->fil", T, ref, T), rtol=1e-7, atol=1e-12)


def test_modal_expansion_seed000_form_with_rayleigh_damping():
    """h_ij = sum_k phi_ik phi_jk / (mu_k (w_k^2 + 2 i zeta_k w_k w - w^2)) with SciPy's modes."""
    alpha, beta = 0.3, 2e-4
    M, C, K = _random_system(4, 7, proportional=True, alpha=alpha, beta=beta)
    lam, Phi = sla.eigh(K, M)
    wk = np.sqrt(lam)
    zk = alpha / (2 * wk) + beta * wk / 2
    mu = np.einsum("ik,ij,jk->k", Phi, M, Phi)
    w = np.linspace(0.1, 40.0, 37)
    ref = np.einsum("ik,jk,fk->fij", Phi, Phi, 1 / (mu * (wk**2 + 2j * zk * wk * w[:, None] - w[:, None] ** 2)))
    H = np.asarray(frf_matrices(M, C, K, w))
    assert np.allclose(H, ref, rtol=1e-9, atol=1e-14)


def test_rayleigh_damping_ratios_and_modal_masses():
    alpha, beta = 0.5, 1e-3
    M, C, K = _random_system(4, 3, proportional=True, alpha=alpha, beta=beta)
    lam, Phi = sla.eigh(K, M)
    wk = np.sqrt(lam)
    md = modes(M, C, K)
    assert np.allclose(2 * np.pi * np.asarray(md.frequency), wk, rtol=1e-10)
    assert np.allclose(md.damping_ratio, alpha / (2 * wk) + beta * wk / 2, rtol=1e-9)
    # modal mass of a proportional-damping mode is phi^T M phi for the same scaling
    Phi_n = Phi / Phi[np.argmax(np.abs(Phi), axis=0), np.arange(4)]
    assert np.allclose(np.asarray(md.modal_mass), np.einsum("ik,ij,jk->k", Phi_n, M, Phi_n), rtol=1e-8)
    assert np.allclose(np.asarray(md.shape), Phi_n, atol=1e-9)


def test_mac_identities():
    M, _, K = _random_system(4, 11)
    _, Phi = sla.eigh(K, M)
    Mw = np.asarray(mac(Phi, weight=M))
    assert np.allclose(np.diag(Mw), 1.0, atol=1e-12)
    assert np.allclose(Mw - np.diag(np.diag(Mw)), 0.0, atol=1e-12)  # mass-orthogonal modes
    _, Q = np.linalg.eigh(K)  # orthogonal for M = I: the plain MAC of Eq. 4.14 is 0
    Mi = np.asarray(mac(Q))
    assert np.allclose(Mi, np.eye(4), atol=1e-12)
    z = Phi[:, 0] * np.exp(0.7j) * 3.0  # invariant to complex scaling
    assert np.isclose(float(mac(z, Phi[:, :1])[0, 0]), 1.0, atol=1e-12)


def test_track_modes_recovers_permutations():
    rng = np.random.default_rng(0)
    n, m, T = 5, 4, 12
    base = rng.normal(size=(n, m))
    drift = np.cumsum(0.02 * rng.normal(size=(T, n, m)), axis=0)
    true = base[None] + drift
    perms = np.stack([rng.permutation(m) for _ in range(T)])
    perms[0] = np.arange(m)
    scrambled = np.stack([true[t][:, perms[t]] for t in range(T)])
    perm, cont = track_modes(scrambled)
    for t in range(T):
        assert np.allclose(scrambled[t][:, np.asarray(perm[t])], true[t])
    assert float(np.min(cont)) > 0.9


def test_eigen_pairs_satisfy_quadratic_problem():
    M, C, K = _random_system(3, 5)
    e = eigen(M, C, K)
    for lam, psi in zip(np.asarray(e.eigenvalue), np.asarray(e.shape).T):
        r = (lam**2 * M + lam * C + K) @ psi
        assert np.linalg.norm(r) < 1e-8 * np.linalg.norm(K) * np.linalg.norm(psi)


@pytest.mark.parametrize("omega", [[0.0, 2.0, 1.0], [-1.0, 0.0, 1.0], [[1.0, 2.0]], [0.0, np.nan]])
def test_bad_frequency_grid(omega):
    M, C, K = _random_system(2, 0)
    with pytest.raises(jflex.JFlexError, match="omega"):
        frf_matrices(M, C, K, np.asarray(omega))


def test_bad_kind_or_method():
    M, C, K = _random_system(2, 0)
    with pytest.raises(jflex.ShapeError, match="kind"):
        frf_matrices(M, C, K, [1.0], kind="compliance")
    with pytest.raises(jflex.ShapeError, match="method"):
        frf_matrices(M, C, K, [1.0], method="fast")


# ---- solver="newton": Newton's method from the undamped modes ---------------------------------


# compiled once per size and shared by the cases: called eagerly, each new size cost about three
# times the compile of the whole solve (its loops dispatched op by op); the eager path is what
# test_newton_solver_refuses_overdamped_modes and test_newton_solver_at_a_mode_crossing call
_newton_modes = jax.jit(lambda M, C, K: modes(M, C, K, solver="newton"))
_eig_modes = jax.jit(lambda M, C, K: modes(M, C, K))
_newton_frf = jax.jit(lambda M, C, K, w, T: frf_matrices(M, C, K, w, T=T, method="modal", solver="newton"))


@pytest.mark.parametrize("n,seed", [(1, 0), (3, 1), (6, 2), (6, 3)])
def test_newton_solver_matches_scipy_eig(n, seed):
    M, C, K = light_system(n, seed)
    Z = np.zeros((n, n))
    lam = sla.eig(-np.block([[K, Z], [Z, -M]]), np.block([[C, M], [M, Z]]), right=False)
    ref = np.sort_complex(lam[lam.imag > 0])
    md = _newton_modes(M, C, K)
    got = np.asarray(md.eigenvalue)
    assert np.allclose(np.sort_complex(got), ref, rtol=1e-10)
    me = _eig_modes(M, C, K)
    assert np.allclose(md.frequency, me.frequency, rtol=1e-10)
    assert np.allclose(md.damping_ratio, me.damping_ratio, rtol=1e-8, atol=1e-12)
    assert np.allclose(md.shape, me.shape, atol=1e-8)
    w = np.linspace(0.0, 1.5 * float(np.max(md.frequency)) * 2 * np.pi, 64)
    T = np.random.default_rng(seed).normal(size=(3, n))
    inv = np.stack([np.linalg.inv(K - wi**2 * M + 1j * wi * C) for wi in w])
    H = np.asarray(_newton_frf(M, C, K, w, T))
    assert np.allclose(H, np.einsum("ij,fjk,lk->fil", T, inv, T), rtol=1e-8, atol=1e-14 * np.abs(inv).max())


def test_newton_solver_gradients_match_finite_differences():
    import jax

    M, C, K = light_system(3, 5)

    def f(s):
        md = modes(M * s[0], C * s[1], K * s[2], solver="newton")
        return jax.numpy.sum(md.frequency) + 10 * jax.numpy.sum(md.damping_ratio) + jax.numpy.abs(md.shape[0, 1])

    s0 = np.array([1.0, 1.0, 1.0])
    g = np.asarray(jax.jit(jax.grad(f))(s0))
    h = 1e-6
    f = jax.jit(f)  # one compile for the six differences (eagerly, each call dispatches the solve op by op)
    fd = np.array([(f(s0 + h * e) - f(s0 - h * e)) / (2 * h) for e in np.eye(3)])
    assert np.allclose(g, fd, rtol=1e-5, atol=1e-8)


def test_default_solver_is_differentiable():
    import jax

    M, C, K = light_system(3, 6)
    f = jax.jit(lambda s: jax.numpy.sum(modes(M, C * s, K).damping_ratio) + jax.numpy.abs(modes(M, C * s, K).shape[1, 0]))
    h = 1e-6
    g = float(jax.jit(jax.grad(f))(1.0))
    assert abs(g - (f(1 + h) - f(1 - h)) / (2 * h)) < 1e-5 * max(1.0, abs(g))


def test_newton_solver_refuses_overdamped_modes():
    # three coordinates, the size the crossing cases below use: the eager solve compiles once per size
    M, K = np.eye(3), np.diag([100.0, 400.0, 900.0])
    C = np.diag([30.0, 1.0, 1.0])  # first mode overdamped (zeta = 1.5)
    with pytest.raises(Exception, match="solver='eig'"):
        np.asarray(modes(M, C, K, solver="newton").frequency)
    md = modes(M, C, K)  # the default handles it
    assert np.isfinite(np.asarray(md.frequency)).all()
    with pytest.raises(jflex.JFlexError, match="solver"):
        modes(M, C, K, solver="qr")


@pytest.mark.parametrize("split", [0.0, 1e-6, 1e-3, 0.05])
def test_newton_solver_at_a_mode_crossing(split):
    """Two modes at (nearly) the same undamped frequency, mixed by non-proportional damping."""
    M = np.eye(3)
    K = np.diag([400.0, 400.0 * (1 + split), 2500.0])
    C = np.array([[0.8, 0.5, 0.1], [0.5, 0.2, 0.0], [0.1, 0.0, 1.0]])
    ref = modes(M, C, K)
    md = modes(M, C, K, solver="newton")
    assert np.allclose(md.eigenvalue, ref.eigenvalue, rtol=1e-10)
