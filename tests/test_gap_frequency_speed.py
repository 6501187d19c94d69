"""The fast paths of the diagnosis's frequency evaluator (:mod:`jflex.gap.frequency._model`) give the
numbers of the plain formulas bit for bit, and its memos never hand back another ``x``'s or
posture's values (a diagnosis's selection moved on a 1e-15 change of the modal estimates)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

import jflex
from jflex.gap.frequency import _model as L
from jflex.gap.frequency._inertia import shifted


@pytest.fixture(scope="module")
def lm():
    rows = [[0.0, 0.0, 0.4, 0.0], [np.pi / 2, 0.1, 0.0, 0.0], [0.0, 0.6, 0.0, 0.0]]
    inertias = [{"mass": 10.0 - 2 * i, "com": [0.2, 0.01, 0.02], "inertia": [0.3, 0.0, 0.4, 0.0, 0.0, 0.5]} for i in range(3)]
    robot = jflex.from_dh(rows, tool=[0.0, 0.5, 0.0, 0.0], inertias=inertias)
    E = jflex.effects
    sites = (L.Site("joint", 0), L.Site("joint", 1, law=E.Hysteretic(eta=1.0)), L.Site("joint", 2, law=E.Fractional(1.0, 0.4)),
             L.Site("orth", 0, 0), L.Site("orth", 0, 1, coupled=True), L.Site("link", 1, 0, frac=0.4), L.Site("link", 1, 1, frac=0.4))
    return L.FrequencyModel(robot, L.Structure(sites, payload=True), "tool")


def _x(rng, lm):
    S = len(lm.structure.springs)
    k = np.log([3e4, 5e4, 2e4, 4e5, 2e5, 8e4, 9e4]) + rng.normal(0, 0.3, S)
    c = np.log([30.0, 2500.0, 40.0, 400.0, 200.0, 80.0, 90.0]) + rng.normal(0, 0.3, S)
    return np.r_[k, c, rng.normal(0, 0.5), rng.normal(0, 0.5)]


def _modes_reference(lm, x, q0):
    # the plain formula: Re/Im of the complex dynamic stiffness stack of stiffness()
    P = lm.mats(q0)
    w_ref = 2 * np.pi * 10.0
    D, M = lm.stiffness(x, P, np.array([w_ref]), True)
    lam, V = L._gen_eig(D[0].real + w_ref**2 * M, M)
    w = np.sqrt(np.maximum(lam, 1e-12))
    for _ in range(4):  # a fractional law: frequency dependent
        D, M = lm.stiffness(x, P, w, True)
        K = D.real + (w**2)[:, None, None] * M[None]
        w = np.sqrt(np.maximum(np.einsum("ir,rij,jr->r", V, K, V) / np.einsum("ir,ij,jr->r", V, M, V), 1e-12))
    D, M = lm.stiffness(x, P, w, True)
    z = np.einsum("ir,rij,jr->r", V, D.imag, V) / (2 * w**2 * np.einsum("ir,ij,jr->r", V, M, V))
    o = np.argsort(w)
    return w[o] / (2 * np.pi), z[o]


def test_modes_bit_for_bit_the_plain_formula(lm):
    rng = np.random.default_rng(0)
    for _ in range(5):
        x, q0 = _x(rng, lm), rng.uniform(-1.5, 1.5, 3)
        f, z = lm.modes(x, q0)
        fr, zr = _modes_reference(lm, x, q0)
        np.testing.assert_array_equal(f, fr)
        np.testing.assert_array_equal(z, zr)


def test_frf_and_jacobian_memos_follow_x_and_posture(lm):
    rng = np.random.default_rng(1)
    freq = np.linspace(2.0, 120.0, 17)
    x1, x2 = _x(rng, lm), _x(rng, lm)
    qa, qb = rng.uniform(-1.5, 1.5, 3), rng.uniform(-1.5, 1.5, 3)
    fresh = lambda x, q: L.FrequencyModel(lm.robot, lm.structure, lm.tool).frf_jacobian(x, q, freq)
    for x, q in ((x1, qa), (x2, qa), (x1, qb), (x2, qb)):
        H = lm.frf(x, q, freq)
        H2, dH = lm.frf_jacobian(x, q, freq)  # reuses frf's solve
        Hf, dHf = fresh(x, q)
        np.testing.assert_array_equal(H, Hf)
        np.testing.assert_array_equal(H2, Hf)
        np.testing.assert_array_equal(dH, dHf)
    # a caller's changes to a returned H do not reach the memo
    H = lm.frf(x1, qa, freq)
    H[:] = 0.0
    np.testing.assert_array_equal(lm.frf(x1, qa, freq), fresh(x1, qa)[0])
    # the analytic derivatives match central differences (payload and coupling included)
    _, dH = lm.frf_jacobian(x1, qa, freq)
    for p in range(x1.size):
        e = np.zeros_like(x1)
        e[p] = 1e-6
        fd = (lm.frf(x1 + e, qa, freq) - lm.frf(x1 - e, qa, freq)) / 2e-6
        np.testing.assert_allclose(dH[p], fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())
    # the solve with D^T (a posture whose matrices are not exactly symmetric) gives the same
    P = lm.mats(qb)
    H_sym, dH_sym = lm.frf_jacobian(x2, qb, freq)
    P.derived["sym"] = False
    try:
        H_gen, dH_gen = lm.frf_jacobian(x2, qb, freq)
    finally:
        P.derived["sym"] = None
    np.testing.assert_allclose(dH_gen, dH_sym, rtol=1e-9, atol=1e-12 * np.abs(dH_sym).max())


def test_shifted_inertia_model_is_not_served_the_cad_values(lm):
    rng = np.random.default_rng(2)
    freq = np.linspace(2.0, 120.0, 9)
    x, q0 = _x(rng, lm), rng.uniform(-1.5, 1.5, 3)
    H0 = lm.frf(x, q0, freq)
    delta = np.zeros(10 * lm.robot.nq)
    delta[0::10] = 0.5  # half a kilogram more on every link
    sh = shifted(lm, delta)
    H1 = sh.frf(x, q0, freq)
    assert np.abs(H1 - H0).max() > 1e-6 * np.abs(H0).max()
    np.testing.assert_array_equal(sh.frf_jacobian(x, q0, freq)[0], H1)
    np.testing.assert_array_equal(lm.frf(x, q0, freq), H0)


@pytest.mark.parametrize("n", [4, 10])
def test_payload_body_is_jflex_payload_in_the_tool_frame(lm, n):
    """A payload of 4 (mass, centre of mass) or 10 (and its rotational inertia) parameters, on a tool
    frame turned and moved on its link: its basis is the linearisation's change with each of the
    link's inertial parameters (the jflex.effects.Payload the model holds: tests/test_gap.py checks
    the FRF against jflex.linear.frf), its analytic derivatives central differences, and it reports
    the body planted, in the tool frame."""
    robot = lm.robot.replace(frame_R=jnp.asarray([[[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]]),
                             frame_p=jnp.asarray([[0.5, 0.1, -0.05]]))
    lp = L.FrequencyModel(robot, L.Structure(lm.structure.springs, n), "tool")
    rng = np.random.default_rng(3)
    x = _x(rng, lm)
    th = L.payload_start(n, 1.5, (0.02, -0.03, 0.05), r=0.03)
    if n == 10:
        th[4:] += [0.2, -0.1, 0.3, 0.01, -0.02, 0.005]
    x = np.r_[x[:14], th, x[15:]]
    q0, freq = np.array([0.3, 0.8, -1.1]), np.array([5.0, 20.0, 40.0, 90.0])
    # the basis: the linearisation's change with each of the link's 10 inertial parameters
    qa = lp.posture(q0)
    dM, dK = lp._payload_basis(qa)
    M0, K0 = lp._linearization(lp.aug, qa)
    link = lp.aug.link_names[lp._payload_frame()[0]]
    for i in range(10):
        M1, K1 = lp._linearization(jflex.effects.Payload(np.eye(10)[i], link=link).modify_robot(lp.aug), qa)
        np.testing.assert_allclose(M1 - M0, dM[:, :, i], atol=1e-12)
        np.testing.assert_allclose(K1 - K0, dK[:, :, i], atol=1e-12)
    _, dH = lp.frf_jacobian(x, q0, freq)
    for p in range(14, 14 + n):
        e = np.zeros_like(x)
        e[p] = 1e-6
        fd = (lp.frf(x + e, q0, freq) - lp.frf(x - e, q0, freq)) / 2e-6
        np.testing.assert_allclose(dH[p], fd, rtol=1e-5, atol=1e-5 * np.abs(fd).max())
    # reported in the tool frame: mass, centre of mass, inertia about it; a physical body
    from jflex.identify import is_consistent

    pp = lp.payload_parameters(x)
    assert pp["mass [kg]"] == pytest.approx(1.5, rel=1e-12) and pp["parameters"] == n
    np.testing.assert_allclose(pp["com (tool frame) [m]"], [0.02, -0.03, 0.05], atol=1e-12)
    assert is_consistent(pp["inertial parameters (link frame)"])
    if n == 4:  # a point mass: no inertia of its own
        np.testing.assert_allclose(pp["inertia about com (tool axes) [kg m^2]"], 0.0, atol=1e-15)
