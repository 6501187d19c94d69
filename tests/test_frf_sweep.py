"""Pole-residue FRFs and the two-stage posture sweep, against the direct inverse of the dynamic
stiffness (an independent formula) and against per-posture ``jflex.frf``."""

import jax
import numpy as np
import pytest

import jflex
from _references import light_system
from jflex.effects import FlexibleJoints, Hysteretic, StructuralDamping
from jflex.linear import PoleResidue, pole_residue, pole_residue_matrices, synthesize_frf


@pytest.mark.parametrize("solver", ["newton", "eig"])
@pytest.mark.parametrize("kind,factor", [("receptance", lambda w: 1.0), ("mobility", lambda w: 1j * w),
                                         ("accelerance", lambda w: -(w**2))])
def test_synthesized_frf_equals_direct_inverse(solver, kind, factor):
    n = 4
    M, C, K = light_system(n, 3)
    T = np.random.default_rng(1).normal(size=(3, n))
    w = np.linspace(0.0, 40.0, 97)
    pr = pole_residue_matrices(M, C, K, T=T, solver=solver)
    assert pr.pole.shape == (n,) and pr.residue.shape == (3, 3, n)
    assert np.all(np.asarray(pr.pole).imag > 0)
    inv = np.stack([np.linalg.inv(K - wi**2 * M + 1j * wi * C) for wi in w])
    ref = np.einsum("ij,fjk,lk->fil", T, inv, T) * np.asarray(factor(w) + 0j).reshape(-1, 1, 1)
    H = np.asarray(synthesize_frf(pr, w, kind=kind))
    assert np.allclose(H, ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())


def test_pole_residue_of_an_overdamped_mode_is_refused():
    M, C, K = np.eye(2), np.diag([50.0, 0.1]), np.diag([100.0, 400.0])  # mode 1: zeta = 2.5
    with pytest.raises(Exception, match="overdamped"):
        jax.block_until_ready(pole_residue_matrices(M, C, K, solver="eig").pole)


def _arm():
    rows = [[0.0, 0.0, 0.4, 0.0], [np.pi / 2, 0.1, 0.0, 0.0], [0.0, 0.6, 0.0, 0.0]]
    inertias = [{"mass": 10.0 - 2 * i, "com": [0.2, 0.01, 0.02], "inertia": [0.3, 0.0, 0.4, 0.0, 0.0, 0.5]} for i in range(3)]
    robot = jflex.from_dh(rows, tool=[0.0, 0.5, 0.0, 0.0], inertias=inertias)
    fj = FlexibleJoints([2e5, 3e5, 1e5], [40.0, 30.0, 20.0], rotor_inertia=[1e-3] * 3, gear_ratio=[100.0] * 3)
    return jflex.Model(robot, [fj])


def test_frf_sweep_matches_per_posture_frf_and_streams_every_block():
    model = _arm()
    rng = np.random.default_rng(0)
    Q = rng.uniform(-1.5, 1.5, (23, 3))  # not a multiple of the block or chunk
    w = 2 * np.pi * np.linspace(1.0, 150.0, 32)
    kw = dict(hold="actuated", frame="tool")
    # the reference: the direct form (inverse of the dynamic stiffness), the whole batch in one block
    ref = jflex.frf_sweep(model, Q, w, method="direct", block_size=len(Q), progress=False, **kw)
    H = jflex.frf_sweep(model, Q, w, chunk_size=10, block_size=4, progress=False, **kw)
    assert H.shape == (23, 32, 3, 3)
    assert np.allclose(H, ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())
    # the pole-residue model of one posture is the same FRF
    pr = jax.jit(lambda q: pole_residue(model, q, **kw))(Q[5])
    assert isinstance(pr, PoleResidue)
    assert np.allclose(np.asarray(synthesize_frf(pr, w)), ref[5], rtol=1e-9, atol=1e-12 * np.abs(ref).max())
    # streaming: every posture exactly once, in order, with the same values
    seen = []
    jflex.frf_sweep(model, Q, w, chunk_size=10, block_size=4, progress=False, kind="mobility",
                    consume=lambda s, Hb: seen.append((s, Hb.copy())), **kw)
    starts = [s for s, _ in seen]
    assert starts == sorted(starts) and starts[0] == 0
    Hm = np.concatenate([Hb for _, Hb in seen])
    assert Hm.shape[0] == 23
    assert np.allclose(Hm, ref * (1j * w)[None, :, None, None], rtol=1e-9, atol=1e-12 * np.abs(ref * w[None, :, None, None]).max())


def test_frf_sweep_bad_inputs():
    model = _arm()
    w = np.linspace(1.0, 100.0, 8)
    with pytest.raises(jflex.ShapeError, match="postures"):
        jflex.frf_sweep(model, np.zeros(3), w, progress=False)
    with pytest.raises(jflex.ShapeError, match="block_size"):
        jflex.frf_sweep(model, np.zeros((2, 3)), w, block_size=0, progress=False)
    with pytest.raises(jflex.ParameterError, match="increasing"):
        jflex.frf_sweep(model, np.zeros((2, 3)), w[::-1], progress=False)
    with pytest.raises(jflex.ShapeError, match="method"):
        jflex.frf_sweep(model, np.zeros((2, 3)), w, method="fast", progress=False)
    # a frequency-dependent effect has no pole-residue model: the direct form is named
    robot = model.rigid
    hyst = jflex.Model(robot, [FlexibleJoints([2e5, 3e5, 1e5]), StructuralDamping(np.diag([2e5]), Hysteretic(eta=0.02), (3,))])
    with pytest.raises(jflex.ParameterError, match="method='direct'"):
        jflex.frf_sweep(hyst, np.zeros((2, 3)), w, hold="actuated", progress=False)


def test_quickly_compiled_sweep_equals_the_optimised_one(monkeypatch):
    # small sweeps run programs compiled without LLVM's optimisation passes (a first call in
    # half the time); they must give the optimised programs' numbers
    from jflex.linear import _frf_sweep

    model = _arm()
    Q = np.random.default_rng(5).uniform(-1.5, 1.5, (9, 3))
    w = 2 * np.pi * np.linspace(1.0, 150.0, 16)
    kw = dict(hold="actuated", frame="tool", progress=False)
    quick = jflex.frf_sweep(model, Q, w, **kw)
    monkeypatch.setattr(_frf_sweep, "QUICK_COMPILE_POSTURES", 0)
    full = jflex.frf_sweep(model, Q, w, **kw)
    np.testing.assert_allclose(quick, full, rtol=1e-10, atol=1e-12 * np.abs(full).max())
