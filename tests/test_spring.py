"""The Spring effect and the damping laws' complex modulus against their closed forms."""

import jax.numpy as jnp
import numpy as np
import pytest

import jflex
from jflex.effects import Fractional, Hysteretic, KelvinVoigt, Spring, complex_modulus, damping_laws
from _sim_helpers import Spring as HandSpring, slider

K = 300.0
W = np.array([0.7, 4.0, 55.0])


def _closed_form(law, w):
    if isinstance(law, KelvinVoigt):
        return 1 + 1j * float(law.k_e) * w
    if isinstance(law, Hysteretic):
        return 1 + 1j * float(law.eta) * np.sign(w)
    return 1 + float(law.k_e) * (1j * w) ** float(law.alpha)


@pytest.mark.parametrize("law", [KelvinVoigt(0.003), Hysteretic(eta=0.04), Fractional(0.02, 0.4, (1e-3, 1e5), 4)],
                         ids=["kelvin_voigt", "hysteretic", "fractional"])
def test_complex_modulus_and_spring_dynamic_stiffness(law):
    np.testing.assert_allclose(complex_modulus(law, W), _closed_form(law, W), rtol=1e-9)
    model = jflex.Model(slider(1.0), [Spring(["j"], [K], law)])
    for w in W:
        D = jflex.dynamic_stiffness(model, jnp.zeros(1), w)
        np.testing.assert_allclose(D, [[K * _closed_form(law, w) - w**2]], rtol=1e-9)


def test_spring_potential_matches_an_independent_spring():
    """Same free vibration as a hand-written 1/2 k x^2 spring (no law: conservative)."""
    ts = np.linspace(0.0, 0.5, 51)
    a = jflex.simulate(jflex.Model(slider(1.0), [Spring([0], [K])]), ts, x0=[0.01], outputs=("j",))["j"]
    b = jflex.simulate(jflex.Model(slider(1.0), [HandSpring(jnp.asarray(K))]), ts, x0=[0.01], outputs=("j",))["j"]
    np.testing.assert_allclose(a, b, atol=1e-8)
    np.testing.assert_allclose(np.asarray(a).ravel(), 0.01 * np.cos(np.sqrt(K) * ts), atol=1e-6)


def test_laws_that_name_themselves_candidates():
    names = {c.candidate for c in damping_laws()}
    assert {"hysteretic_damping", "fractional_damping"} <= names
    assert KelvinVoigt not in damping_laws()


def test_bad_spring():
    with pytest.raises(jflex.ParameterError, match="Spring.stiffness"):
        Spring(["j"], [-1.0])
    with pytest.raises(jflex.ShapeError, match="Spring.stiffness"):
        Spring(["j"], [1.0, 2.0])
    with pytest.raises(jflex.ParameterError, match="Spring.law"):
        Spring(["j"], [1.0], law="viscous")
    with pytest.raises(jflex.ShapeError, match="unknown joint 'nope'"):
        jflex.dynamic_stiffness(jflex.Model(slider(1.0), [Spring(["nope"], [1.0])]), jnp.zeros(1), 1.0)
