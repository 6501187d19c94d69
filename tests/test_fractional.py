"""Fractional Voigt-Kelvin damping: the rational approximation against (i omega)^alpha in its band,
the time-domain filter against a Grunwald-Letnikov reference, and alpha = 1 against viscous."""

import jax.numpy as jnp
import numpy as np
import pytest

import jflex
from jflex.effects import Fractional, KelvinVoigt, StructuralDamping, grunwald_letnikov, oustaloup_response
from _sim_helpers import slider

BAND = (1e-2, 1e4)


@pytest.mark.parametrize("alpha", [0.185, 0.218, 0.5, 1.0])
def test_approximation_matches_exact_power_in_band(alpha):
    """The stated accuracy (docstring of Fractional): inside [100 w_lo, w_hi / 100] the gain error
    is below 1 % and the phase error below 1 degree with order 6 over 6 decades."""
    w = np.logspace(0, 2, 200)
    G = np.asarray(oustaloup_response(alpha, *BAND, 6, w))
    ex = (1j * w) ** alpha
    assert np.max(np.abs(np.abs(G) / np.abs(ex) - 1)) < 0.01
    assert np.degrees(np.max(np.abs(np.angle(G / ex)))) < 1.0


def _model(law, k=400.0, m=1.0):
    return jflex.Model(slider(m), [_Spring(jnp.asarray(k)), StructuralDamping(jnp.array([[k]]), law, coords=(0,))])


from _sim_helpers import Spring as _Spring  # noqa: E402


def test_time_domain_filter_against_grunwald_letnikov():
    alpha, k_e = 0.5, 0.01
    law = Fractional(k_e, alpha, BAND, order=6)
    model = _model(law)
    h = 1e-3
    ts = np.arange(0, 2.0 + h / 2, h)
    r = jflex.simulate(model, ts, x0=[0.0], xd0=[0.5], rtol=1e-10, atol=1e-12, outputs=("j", "z"))
    x, z = np.asarray(r["j"]), np.asarray(r["z"])
    d_filter = np.array([float(law.derivative(jnp.array([xi]), jnp.asarray(zi))[0]) for xi, zi in zip(x[::20], z[::20])])
    d_gl = grunwald_letnikov(x, h, alpha)[::20]
    scale = np.max(np.abs(d_gl))
    np.testing.assert_allclose(d_filter[5:], d_gl[5:], atol=0.02 * scale)


def test_alpha_one_equals_viscous():
    k, k_e = 400.0, 0.002
    frac, kv = _model(Fractional(k_e, 1.0, (1e-3, 1e5), order=6), k), _model(KelvinVoigt(k_e), k)
    x0 = jnp.zeros(1)
    for w in (0.5, 20.0, 300.0):
        np.testing.assert_allclose(jflex.dynamic_stiffness(frac, x0, w), jflex.dynamic_stiffness(kv, x0, w), rtol=1e-10)
        np.testing.assert_allclose(jflex.dynamic_stiffness(kv, x0, w), [[k * (1 + 1j * k_e * w) - w**2]], rtol=1e-12)
    ts = np.linspace(0, 2, 101)
    # start from x = 0 (zero history is the Riemann-Liouville convention; an initial offset
    # would be a step at t = 0, whose first derivative is an impulse)
    a = jflex.simulate(frac, ts, xd0=[0.2], rtol=1e-10, atol=1e-12, outputs=("j",))["j"]
    b = jflex.simulate(kv, ts, xd0=[0.2], rtol=1e-10, atol=1e-12, outputs=("j",))["j"]
    np.testing.assert_allclose(a, b, atol=2e-3 * 0.01)


def test_fractional_dynamic_stiffness_is_exact_power():
    k, k_e, alpha = 400.0, 0.02, 0.3
    model = _model(Fractional(k_e, alpha, BAND, 4), k)
    for w in (-7.0, 3.0, 50.0):
        D = jflex.dynamic_stiffness(model, jnp.zeros(1), w)
        np.testing.assert_allclose(D, [[k * (1 + k_e * (1j * w) ** alpha) - w**2]], rtol=1e-10)


def test_bad_fractional_parameters():
    with pytest.raises(jflex.ParameterError, match="alpha"):
        Fractional(0.1, 1.5)
    with pytest.raises(jflex.ParameterError, match="band"):
        Fractional(0.1, 0.5, band=(10.0, 1.0))
