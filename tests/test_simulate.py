"""simulate: 1-DOF closed forms (seed 000), inputs and jumps, energy, gradients, failures."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jflex
from _sim_helpers import oscillator, rotor

TOL = 1e-6  # closed-form agreement at rtol 1e-10


def _free(m, k, c, x0, v0, t):
    """Closed-form free response of m xdd + c xd + k x = 0 (under, critical, over)."""
    wn = np.sqrt(k / m)
    z = c / (2 * np.sqrt(k * m))
    if z < 1:
        wd = wn * np.sqrt(1 - z**2)
        return np.exp(-z * wn * t) * (x0 * np.cos(wd * t) + (v0 + z * wn * x0) / wd * np.sin(wd * t))
    if z == 1:
        return np.exp(-wn * t) * (x0 + (v0 + wn * x0) * t)
    s1, s2 = -wn * (z - np.sqrt(z**2 - 1)), -wn * (z + np.sqrt(z**2 - 1))
    A = (v0 - s2 * x0) / (s1 - s2)
    return A * np.exp(s1 * t) + (x0 - A) * np.exp(s2 * t)


@pytest.mark.parametrize("zeta", [0.05, 1.0, 2.5])
def test_free_response_matches_closed_form(zeta):
    m, k = 2.0, 50.0
    c = 2 * zeta * np.sqrt(k * m)
    ts = np.linspace(0, 3, 61)
    r = jflex.simulate(oscillator(m, k, c), ts, x0=[0.01], xd0=[0.2], rtol=1e-10, atol=1e-12, outputs=("j",))
    np.testing.assert_allclose(r["j"], _free(m, k, c, 0.01, 0.2, ts), atol=TOL * 0.05)


def test_forced_steady_state_amplitude_and_phase():
    m, k, c, F, f = 1.0, 100.0, 2.0, 1.0, 2.0
    w = 2 * np.pi * f
    ts = np.linspace(0, 12, 1201)
    u = jflex.Chirp([F], f, f, duration=20.0)  # f0 = f1: a pure sine F sin(w t)
    r = jflex.simulate(oscillator(m, k, c), ts, inputs=u, rtol=1e-10, atol=1e-12, outputs=("j",))
    X = F / np.sqrt((k - m * w**2) ** 2 + (c * w) ** 2)
    phi = np.arctan2(c * w, k - m * w**2)
    tail = ts > 10  # the transient decays as exp(-t): below 1e-4 of X after 10 s
    np.testing.assert_allclose(r["j"][tail], X * np.sin(w * ts[tail] - phi), atol=3e-4 * X)


def test_step_input_is_landed_on_not_smeared():
    m, k, F, t0 = 1.0, 100.0, 2.0, 0.5037
    ts = np.linspace(0, 1.5, 151)
    r = jflex.simulate(oscillator(m, k), ts, inputs=jflex.Step([F], t0), rtol=1e-10, atol=1e-12, outputs=("j",))
    ref = np.where(ts >= t0, F / k * (1 - np.cos(np.sqrt(k / m) * (ts - t0))), 0.0)
    np.testing.assert_allclose(r["j"], ref, atol=1e-9)


def test_duhamel_integral_for_a_ramp():
    """Response to a ramp against the Duhamel integral evaluated numerically (seed 000)."""
    m, k, c = 1.0, 100.0, 1.0
    ts = np.linspace(0, 2, 2001)
    u = jflex.Ramp([3.0], 0.2, 0.7)
    r = jflex.simulate(oscillator(m, k, c), ts, inputs=u, rtol=1e-10, atol=1e-12, outputs=("j",))
    wn, z = np.sqrt(k / m), c / (2 * np.sqrt(k * m))
    wd = wn * np.sqrt(1 - z**2)
    F = 3.0 * np.clip((ts - 0.2) / 0.5, 0, 1)
    h = np.exp(-z * wn * ts) * np.sin(wd * ts) / (m * wd)
    duh = np.array([np.trapezoid(F[: i + 1] * h[i::-1], ts[: i + 1]) for i in range(ts.size)])
    np.testing.assert_allclose(r["j"], duh, atol=2e-6)


def test_sampled_input_equals_analytic_ramp():
    m, k = 1.0, 100.0
    ts = np.linspace(0, 1, 101)
    ramp = jflex.Ramp([1.0], 0.2, 0.6)
    samp = jflex.Sampled(np.array([0.0, 0.2, 0.6, 1.0]), np.array([0.0, 0.0, 1.0, 1.0]))
    a = jflex.simulate(oscillator(m, k), ts, inputs=ramp, rtol=1e-10, atol=1e-12, outputs=("j",))
    b = jflex.simulate(oscillator(m, k), ts, inputs=samp, rtol=1e-10, atol=1e-12, outputs=("j",))
    np.testing.assert_allclose(a["j"], b["j"], atol=1e-8)


def test_energy_balance_with_damping_and_input():
    """E(t) - E(0) = work of input and damper, and the damper's share is -int c xd^2 dt."""
    m, k, c = 1.0, 100.0, 0.6
    ts = np.linspace(0, 3, 3001)
    r = jflex.simulate(oscillator(m, k, c), ts, x0=[0.02], inputs=jflex.Step([0.5], 1.0, 2.0),
                       rtol=1e-11, atol=1e-13, outputs=("energy", "work", "j", "j_d"))
    E, W, x, v = (np.asarray(r[n]) for n in ("energy", "work", "j", "j_d"))
    np.testing.assert_allclose(E - E[0], W, atol=1e-9)
    # independent: a constant force F on [1, 2] s does F (x(2) - x(1)); the damper -int c v^2 dt
    i1, i2 = 1000, 2000
    damper = -c * np.concatenate([[0], np.cumsum(0.5 * np.diff(ts) * (v[1:] ** 2 + v[:-1] ** 2))])
    np.testing.assert_allclose(W[-1], 0.5 * (x[i2] - x[i1]) + damper[-1], atol=1e-7)
    np.testing.assert_allclose(W[:i1], damper[:i1], atol=1e-7)


def test_undamped_energy_is_conserved():
    ts = np.linspace(0, 10 * 2 * np.pi / 10.0, 201)
    r = jflex.simulate(oscillator(1.0, 100.0), ts, x0=[0.1], rtol=1e-12, atol=1e-14, outputs=("energy",),
                       solver=diffrax.Dopri8())
    E = np.asarray(r["energy"])
    assert np.max(np.abs(E - E[0])) / E[0] < 1e-8


def test_gradient_through_simulate_matches_finite_differences():
    ts = jnp.linspace(0, 1.0, 11)

    def final(k, c):
        mdl = oscillator(1.0, k, c)
        return jflex.simulate(mdl, ts, x0=jnp.array([0.01]), xd0=jnp.array([0.2]),
                              rtol=1e-10, atol=1e-12, outputs=("j",))["j"][-1]

    g = jax.grad(final, argnums=(0, 1))(100.0, 0.5)
    h = 1e-5
    fd_k = (final(100.0 + h, 0.5) - final(100.0 - h, 0.5)) / (2 * h)
    fd_c = (final(100.0, 0.5 + h) - final(100.0, 0.5 - h)) / (2 * h)
    np.testing.assert_allclose(g, [fd_k, fd_c], rtol=1e-5)


def test_solver_failure_is_a_clear_error():
    with pytest.raises(jflex.SolverError, match="max_steps"):
        jflex.simulate(oscillator(1.0, 1e4), np.linspace(0, 10, 3), x0=[0.1], max_steps=16)
    with pytest.raises(jflex.SolverError, match="NaN"):
        jflex.simulate(oscillator(1.0, 100.0), np.linspace(0, 1, 3), x0=[np.nan])


def test_bad_arguments_raise_named_errors():
    with pytest.raises(jflex.ShapeError, match="unknown output"):
        jflex.simulate(oscillator(), np.linspace(0, 1, 3), outputs=("nope",))
    with pytest.raises(jflex.ShapeError, match="x0"):
        jflex.simulate(oscillator(), np.linspace(0, 1, 3), x0=[0.0, 1.0])
    with pytest.raises(jflex.ParameterError):
        jflex.Ramp([1.0], 1.0, 0.5)


def test_vmap_batch_of_responses():
    ts = jnp.linspace(0, 0.5, 6)
    mdl = oscillator(1.0, 100.0, 0.5)
    run = lambda x0: jflex.simulate(mdl, ts, x0=x0[None], rtol=1e-8, atol=1e-10, outputs=("j",))["j"]
    xs = jax.jit(jax.vmap(run))(jnp.array([0.01, 0.02]))
    ref = np.stack([_free(1.0, 100.0, 0.5, a, 0.0, np.asarray(ts)) for a in (0.01, 0.02)])
    np.testing.assert_allclose(xs, ref, atol=1e-6)


def test_flexible_joint_tends_to_rigid_joint():
    """jflex.effects.FlexibleJoints (issue 3, reduced model): as K grows the joint angle tends to
    the rigid joint carrying the motor inertia, tau t^2 / (2 (I + J))."""
    J, I, tau = 0.05, 0.1, 0.2
    ts = np.linspace(0, 0.5, 11)
    rigid = jflex.simulate(jflex.Model(rotor(I)), ts, inputs=jflex.Step([tau], 0.0), rtol=1e-10, atol=1e-12, outputs=("j1",))
    # rigid joint with the motor's inertia added: closed form tau t^2 / (2 (I + J))
    errs = []
    for K in (1e2, 1e4, 1e6):
        mdl = jflex.Model(rotor(I), [jflex.effects.FlexibleJoints([K], rotor_inertia=[J], joints=[0], coupling=False)])
        r = jflex.simulate(mdl, ts, inputs=jflex.Step([tau], 0.0), rtol=1e-10, atol=1e-12, outputs=("j1",),
                           solver=diffrax.Kvaerno5(), max_steps=200_000)
        errs.append(np.max(np.abs(np.asarray(r["j1"]) - tau * ts**2 / (2 * (I + J)))))
    assert errs[0] > errs[1] > errs[2]
    assert errs[2] < 1e-5
    np.testing.assert_allclose(rigid["j1"], tau * ts**2 / (2 * I), rtol=1e-8, atol=1e-12)
