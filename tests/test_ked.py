"""Modal superposition against direct integration; periodic steady state; damping laws."""

import diffrax
import jax.numpy as jnp
import numpy as np
import pytest

from jflex import fem

_TOL = 1e-6


def _system(seed=0, n=4):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    M = A @ A.T + n * np.eye(n)
    B = rng.normal(size=(n, n))
    K = 1e4 * (B @ B.T + n * np.eye(n))
    return M, K


@pytest.mark.parametrize("damping", [fem.ModalDamping(0.05), fem.RayleighDamping(2.0, 1e-4)])
def test_all_modes_equal_direct_integration(damping):
    M, K = _system()
    n_pose, period = 40, 0.5
    t = np.arange(n_pose) * period / n_pose
    F = np.stack([np.sin(2 * np.pi * t / period) * (1 + k) for k in range(4)], 1) * 100.0
    Ms, Ks = np.repeat(M[None], n_pose, 0), np.repeat(K[None], n_pose, 0)
    sol = fem.ked_transient(Ms, Ks, F, period, damping, n_periods=2)
    C = np.asarray(damping.matrix(M, K))
    # Reference: the same ODE, load interpolated linearly between poses (as the modal step assumes).
    tt = np.arange(2 * n_pose + 1) * period / n_pose
    FF = np.concatenate([F, F, F[:1]])
    load = diffrax.LinearInterpolation(ts=jnp.asarray(tt), ys=jnp.asarray(FF))
    Minv = np.linalg.inv(M)

    def vf(t, y, args):
        u, v = y[:4], y[4:]
        return jnp.concatenate([v, Minv @ (load.evaluate(t) - C @ v - K @ u)])

    ref = diffrax.diffeqsolve(
        diffrax.ODETerm(vf), diffrax.Tsit5(), 0.0, tt[-2], 1e-4, jnp.zeros(8),
        saveat=diffrax.SaveAt(ts=jnp.asarray(tt[:-1])),
        stepsize_controller=diffrax.PIDController(rtol=1e-11, atol=1e-14, jump_ts=jnp.asarray(tt)),
        max_steps=200000,
    )
    U = np.asarray(ref.ys)[:, :4]
    np.testing.assert_allclose(sol.U, U, atol=_TOL * np.abs(U).max())


def test_periodic_state_is_the_limit_of_the_transient():
    M, K = _system(1)
    n_pose, period = 30, 0.05
    t = np.arange(n_pose) * period / n_pose
    # a time-varying system: stiffness breathing over the period
    Ks = np.stack([K * (1 + 0.3 * np.cos(2 * np.pi * s / period)) for s in t])
    Ms = np.stack([M * (1 + 0.1 * np.sin(2 * np.pi * s / period)) for s in t])
    F = np.stack([np.cos(2 * np.pi * t / period + k) for k in range(4)], 1)
    d = fem.ModalDamping(0.1)
    per = fem.ked_periodic(Ms, Ks, F, period, d)
    tr = fem.ked_transient(Ms, Ks, F, period, d, n_periods=120)
    np.testing.assert_allclose(per.U, tr.U[-n_pose:], atol=1e-8 * np.abs(per.U).max())


def test_newmark_converges_to_modal_for_a_time_varying_system():
    M, K = _system(2)
    n_pose, period = 200, 0.05
    t = np.arange(n_pose) * period / n_pose
    ph = 2 * np.pi * t / period
    Ks = np.stack([K * (1 + 0.3 * np.cos(p)) for p in ph])
    Ms = np.stack([M * (1 + 0.1 * np.sin(p)) for p in ph])
    F = np.stack([np.cos(ph + k) for k in range(4)], 1)
    d = fem.ModalDamping(0.1)
    per = fem.ked_periodic(Ms, Ks, F, period, d)
    Cs = np.stack([np.asarray(d.matrix(m, k)) for m, k in zip(Ms, Ks)])
    nm = fem.newmark(Ms, Cs, Ks, F, period, n_periods=30, substeps=4)
    # Two discretisations of one ODE (frozen vs interpolated matrices): they agree to O(dt).
    err = np.abs(np.asarray(nm.U) - np.asarray(per.U)).max() / np.abs(per.U).max()
    assert err < 2e-2


def test_static_correction_recovers_truncated_modes_quasistatically():
    M, K = _system(3, n=6)
    n_pose, period = 20, 100.0  # loads far slower than every mode: response ~ static
    t = np.arange(n_pose) * period / n_pose
    F = np.stack([np.sin(2 * np.pi * t / period) * (k + 1) for k in range(6)], 1)
    Ms, Ks = np.repeat(M[None], n_pose, 0), np.repeat(K[None], n_pose, 0)
    r = fem.ked_periodic(Ms, Ks, F, period, fem.ModalDamping(0.05), n_modes=2, static_correction=True)
    static = np.linalg.solve(K, F.T).T
    np.testing.assert_allclose(r.U, static, atol=1e-4 * np.abs(static).max())


def test_sdof_overdamped_and_stiff_modes_are_finite():
    M = np.eye(2)
    K = np.diag([1.0, 1e14])
    Ms, Ks = np.repeat(M[None], 10, 0), np.repeat(K[None], 10, 0)
    F = np.ones((10, 2))
    r = fem.ked_periodic(Ms, Ks, F, 1.0, fem.RayleighDamping(0.0, 1e-3))
    assert np.all(np.isfinite(r.U))
    np.testing.assert_allclose(r.U[:, 1], 1e-14, rtol=1e-6)  # the stiff mode is static
