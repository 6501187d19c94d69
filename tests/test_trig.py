"""The batch kernels' cosine and sine (jflex/_trig.py) against the C library through NumPy, their
derivatives against the closed forms, and the batched kernels free of library calls."""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jflex
from jflex._sweep import _program
from jflex._trig import cos_sin as _library_cos_sin
from jflex._trig import vectorised


def cos_sin(x):
    with vectorised():
        return _library_cos_sin(x)


def _ulps(got, ref):
    return np.abs(got - ref) / np.spacing(np.abs(ref))


@pytest.mark.parametrize("limit", [np.pi / 4, 4.0, 1e3, 1.6e6])
def test_within_two_units_in_the_last_place_of_the_c_library(limit):
    x = np.random.default_rng(0).uniform(-limit, limit, 200_000)
    c, s = (np.asarray(a) for a in jax.jit(cos_sin)(x))
    for got, ref in ((c, np.cos(x)), (s, np.sin(x))):
        big = np.abs(ref) > 1e-3
        assert _ulps(got[big], ref[big]).max() <= 2.0
        # near a zero the error is absolute: the reduced angle's own rounding
        assert np.abs(got - ref).max() <= 2.3e-16


def test_quadrant_edges_and_special_values():
    k = np.arange(-40, 41)
    edges = np.concatenate([k * np.pi / 2, k * np.pi / 4, np.nextafter(k * np.pi / 4, np.inf),
                            np.nextafter(k * np.pi / 4, -np.inf), [0.0, -0.0, 1e-300, -1e-300]])
    c, s = (np.asarray(a) for a in jax.jit(cos_sin)(edges))
    np.testing.assert_allclose(c, np.cos(edges), rtol=0, atol=2.3e-16)
    np.testing.assert_allclose(s, np.sin(edges), rtol=0, atol=2.3e-16)
    c, s = (np.asarray(a) for a in cos_sin(np.array([np.inf, -np.inf, np.nan])))
    assert np.isnan(c).all() and np.isnan(s).all()


def test_derivatives_are_minus_sine_and_cosine():
    x = jnp.linspace(-7.0, 7.0, 29)
    dc, ds = jax.vmap(jax.jacfwd(cos_sin))(x)
    np.testing.assert_allclose(dc, -np.sin(x), rtol=0, atol=1e-15)
    np.testing.assert_allclose(ds, np.cos(x), rtol=0, atol=1e-15)
    g = jax.grad(lambda a: cos_sin(a)[0] * cos_sin(a)[1])(0.7)  # reverse mode
    np.testing.assert_allclose(g, np.cos(1.4), rtol=1e-14)


def test_float32_takes_the_library_functions():
    x = jnp.linspace(-3.0, 3.0, 11, dtype=jnp.float32)
    c, s = cos_sin(x)
    assert c.dtype == jnp.float32 and s.dtype == jnp.float32
    np.testing.assert_array_equal(np.asarray(c), np.asarray(jnp.cos(x)))


def test_batched_kernels_call_no_sine_or_cosine():
    # a call into the C library inside a fused loop keeps XLA:CPU from vectorising the loop; outside
    # batch programs the kernels keep jnp.cos/jnp.sin, which trace and compile faster
    robot = jflex.load_robot("ur5")
    q = jnp.zeros((64, robot.nq))
    library = re.compile(r"\b(sine|cosine)\(")
    for fn in (jflex.rnea, jflex.aba):
        item = lambda a, f=fn: f(robot, a, a, a)
        for program in ("vmap", "barriers", "blocks"):
            text = _program(item, program=program, batch_size=16, devices=[]).lower(q).compile().as_text()
            assert not library.search(text), (fn.__name__, program)
        assert library.search(jax.jit(jax.vmap(item)).lower(q).compile().as_text()), fn.__name__
    x = np.linspace(-2, 2, 10 * robot.nq).reshape(10, robot.nq)
    out = jflex.batched(lambda a: jflex.rnea(robot, a, a, a))(x)
    ref = jax.vmap(lambda a: jflex.rnea(robot, a, a, a))(x)
    np.testing.assert_allclose(out, ref, rtol=1e-13, atol=1e-13)
