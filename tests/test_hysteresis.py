"""Hysteretic damping: complex stiffness in frequency, Masing rule in time."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

import jflex
from jflex.effects import Hysteretic, StructuralDamping, masing_force, virgin_curve
from _sim_helpers import Spring, slider

H0, DELTA = 0.189, 4.884e-4  # seed 004 Table V


def test_complex_stiffness_in_frequency():
    k, eta = 300.0, 0.02
    model = jflex.Model(slider(1.0), [Spring(jnp.asarray(k)), StructuralDamping(jnp.array([[k]]), Hysteretic(eta, H0, DELTA), coords=(0,))])
    for w in (-5.0, 2.0, 40.0):
        D = jflex.dynamic_stiffness(model, jnp.zeros(1), w)
        np.testing.assert_allclose(D, [[k * (1 + 1j * eta * np.sign(w)) - w**2]], rtol=1e-12)


def test_virgin_curve_values():
    # y(delta) = h0 (1 - 1/4); odd; slope 2 h0 / delta at 0
    np.testing.assert_allclose(virgin_curve(DELTA, H0, DELTA), 0.75 * H0)
    np.testing.assert_allclose(virgin_curve(-DELTA, H0, DELTA), -0.75 * H0)
    g = jax.grad(lambda x: virgin_curve(x, H0, DELTA))(1e-12)
    np.testing.assert_allclose(g, 2 * H0 / DELTA, rtol=1e-6)


def test_masing_states_follow_the_explicit_rule():
    """Integrate the law's memory states along a prescribed decaying oscillation and compare the
    force with the explicit Masing rule (reversals located on a fine sampling)."""
    law = Hysteretic(0.0, H0, DELTA, reversal_rate=1e5)
    A, lam, f = 3 * DELTA, 0.4, 2.0
    xf = lambda t: A * jnp.exp(-lam * t) * jnp.sin(2 * jnp.pi * f * t)
    P, K = jnp.eye(1), jnp.eye(1)

    def rhs(t, z, args):
        v = jax.grad(xf)(t)
        return law.state_rate(K, xf(t)[None], v[None], z, P)

    ts = np.linspace(0, 2.0, 4001)
    sol = diffrax.diffeqsolve(diffrax.ODETerm(rhs), diffrax.Kvaerno5(), 0.0, 2.0, None, law.initial_state(1, 1),
                              saveat=diffrax.SaveAt(ts=jnp.asarray(ts)),
                              stepsize_controller=diffrax.PIDController(rtol=1e-8, atol=1e-11), max_steps=200_000)
    F = np.asarray(sol.ys)[:, 1]
    ref = masing_force(np.asarray(jax.vmap(xf)(jnp.asarray(ts))), H0, DELTA)
    np.testing.assert_allclose(F, ref, atol=0.01 * H0)
    # loops dissipate: the force leads the displacement, so int F dx over the motion is > 0
    x = np.asarray(jax.vmap(xf)(jnp.asarray(ts)))
    assert np.sum(0.5 * (F[1:] + F[:-1]) * np.diff(x)) > 0
