"""Fourier excitation (seed 003 Eq. 3.8) and its optimisation (Eqs. 3.9-3.11); spectral
differentiation (section 3.2.5) against closed-form derivatives."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jflex
from jflex import identify as idf

from _identify_helpers import staubli_like
from conftest import SLOW


def test_fourier_trajectory_derivatives_match_autodiff():
    rng = np.random.default_rng(0)
    tr = idf.FourierTrajectory(jnp.asarray(rng.normal(size=(3, 5))), jnp.asarray(rng.normal(size=(3, 5))),
                               jnp.asarray([0.1, -0.2, 0.3]), jnp.asarray(2 * np.pi * 0.1))
    for t in [0.0, 1.3, 7.7]:
        q, qd, qdd = tr(t)
        assert np.allclose(jax.jacfwd(lambda s: tr(s)[0])(t), qd, atol=1e-12)
        assert np.allclose(jax.jacfwd(lambda s: tr(s)[1])(t), qdd, atol=1e-12)
    q0, _, _ = tr(0.0)
    q1, _, _ = tr(10.0)  # one period later
    assert np.allclose(q0, q1)


def test_spectral_derivatives_of_periodic_signal():
    T, n = 10.0, 1000
    t = np.arange(n) * T / n
    w = 2 * np.pi / T
    q = np.stack([np.sin(3 * w * t) + 0.5 * np.cos(7 * w * t), np.cos(w * t)], axis=1)
    qd_ref = np.stack([3 * w * np.cos(3 * w * t) - 3.5 * w * np.sin(7 * w * t), -w * np.sin(w * t)], axis=1)
    qdd_ref = np.stack([-9 * w**2 * np.sin(3 * w * t) - 24.5 * w**2 * np.cos(7 * w * t), -(w**2) * np.cos(w * t)], axis=1)
    noise = 1e-3 * np.random.default_rng(0).normal(size=q.shape)
    qf, qd, qdd = idf.spectral_derivatives(q + noise, T / n, cutoff=1.0)
    assert np.abs(qf - q).max() < 5e-4
    assert np.abs(qd - qd_ref).max() < 5e-3 * np.abs(qd_ref).max()
    assert np.abs(qdd - qdd_ref).max() < 2e-2 * np.abs(qdd_ref).max()
    _, qd0, qdd0 = idf.spectral_derivatives(q, T / n)
    assert np.allclose(qd0, qd_ref, atol=1e-9) and np.allclose(qdd0, qdd_ref, atol=1e-8)
    assert np.allclose(idf.fft_lowpass(q + noise, T / n, 1.0), qf)


@pytest.mark.slow
def test_design_excitation_improves_condition_within_limits():
    robot = staubli_like(0)
    robot = robot.replace(lower=jnp.array([-2.5, -0.5, -2.2]), upper=jnp.array([0.5, 2.6, 0.1]))
    bp = idf.base_parameters(robot)
    res = idf.design_excitation(robot, bp, n_harmonics=3, n_samples=40, velocity_limit=[2.6, 2.6, 2.6],
                                workspace=("tool", [-1.0, -2.0, 0.1], [2.0, 1.0, 2.6]), max_steps=300 if SLOW else 60,
                                penalties=(1e2, 1e4))
    # Independent evaluation on a 4x finer grid of the designed trajectory.
    t = np.linspace(0, float(res.trajectory.period), 160, endpoint=False)
    q, qd, qdd = (np.asarray(a) for a in res.trajectory.sample(t))
    A = np.asarray(bp.columns(idf.Regressor(viscous=False, coulomb=False).stack(robot, q, qd, qdd)))
    s = np.linalg.svd(A, compute_uv=False)
    assert res.history[-1] < 1e3 and s[0] / s[-1] < 2 * res.cond
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    rng = hi - lo
    assert np.all(q >= lo - 0.02 * rng) and np.all(q <= hi + 0.02 * rng)
    assert np.all(np.abs(qd) <= 2.6 * 1.02)
    p = np.stack([np.asarray(jflex.frame_placement(robot, qq, "tool"))[:3, 3] for qq in q[::8]])
    assert np.all(p[:, 2] >= 0.1 - 0.05) and np.all(p[:, 2] <= 2.65)
