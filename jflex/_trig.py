"""Cosine and sine of joint angles as plain arithmetic, so XLA:CPU can vectorise batch kernels.

XLA:CPU lowers ``cos`` and ``sin`` to calls into the C library, one element at a time; a single
such call inside a fused loop keeps LLVM from vectorising the whole loop. On the 7-joint Panda
the batched RNEA and ABA ran about 2x slower for their seven sines and cosines than for the rest
of their arithmetic. Here both come from one range reduction and two short polynomials (adds,
multiplies, a rounding and selects), which vectorise.

That form is some forty operations where ``jnp.cos`` is one, and tracing and compiling them costs
more than it saves outside large batches: with it everywhere, the gap diagnosis of the built-in
demo traced and compiled 17.1 s instead of 12.3. So :func:`cos_sin` takes it only while
:func:`vectorised` is active, which ``jflex.batched`` and ``jflex.sweep`` do while tracing their
programs; elsewhere it is ``jnp.cos`` and ``jnp.sin``.

Method: Cody-Waite reduction by pi/2 with pi/2 split into two 33-bit parts and a 53-bit tail, so
``n * part`` is exact for ``|n| < 2**20`` (``|x|`` up to about 1.6e6 rad); the kernels on
``[-pi/4, pi/4]`` are those of fdlibm (Sun Microsystems, ``k_sin.c`` and ``k_cos.c``), with its
compensated ``1 - z/2``. Results agree with the C library to about one unit in the last place
over that range; beyond it, the reduction loses a few bits more than the angle's own rounding
(``tests/test_trig.py`` measures both). Float32 and other dtypes take ``jnp.cos``/``jnp.sin``.
"""

from __future__ import annotations

import contextlib
import contextvars

import jax
import jax.numpy as jnp

_INV_PIO2 = 6.36619772367581382433e-01
_PIO2_1 = 1.57079632673412561417e00  # first 33 bits of pi/2
_PIO2_2 = 6.07710050630396597660e-11  # next 33 bits
_PIO2_2T = 2.02226624879595063154e-21  # pi/2 - _PIO2_1 - _PIO2_2
_S = (-1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04,
      2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10)
_C = (4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05,
      -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11)


def _horner(z, coefficients):
    acc = coefficients[-1]
    for c in reversed(coefficients[:-1]):
        acc = c + z * acc
    return acc


def _reduced(x):
    n = jnp.round(x * _INV_PIO2)
    r = ((x - n * _PIO2_1) - n * _PIO2_2) - n * _PIO2_2T
    z = r * r
    sin_r = r + r * z * _horner(z, _S)
    hz = 0.5 * z
    w = 1.0 - hz
    cos_r = w + (((1.0 - w) - hz) + z * z * _horner(z, _C))
    quadrant = n - 4.0 * jnp.floor(0.25 * n)  # 0, 1, 2 or 3, exactly
    odd = (quadrant == 1.0) | (quadrant == 3.0)
    s = jnp.where(odd, cos_r, sin_r)
    c = jnp.where(odd, sin_r, cos_r)
    s = jnp.where(quadrant >= 2.0, -s, s)
    c = jnp.where((quadrant == 1.0) | (quadrant == 2.0), -c, c)
    return c, s


@jax.custom_jvp
def _cos_sin64(x):
    return _reduced(x)


@_cos_sin64.defjvp
def _cos_sin64_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    c, s = _cos_sin64(x)
    return (c, s), (-s * dx, c * dx)


_VECTORISED = contextvars.ContextVar("jflex_vectorised_trig", default=False)


@contextlib.contextmanager
def vectorised():
    """While active (at trace time), :func:`cos_sin` of float64 values is the arithmetic form."""
    token = _VECTORISED.set(True)
    try:
        yield
    finally:
        _VECTORISED.reset(token)


def cos_sin(x):
    """``(cos(x), sin(x))``: inside :func:`vectorised` and for float64 by the arithmetic above,
    else by ``jnp.cos`` and ``jnp.sin``."""
    x = jnp.asarray(x)
    if x.dtype != jnp.float64 or not _VECTORISED.get():
        return jnp.cos(x), jnp.sin(x)
    return _cos_sin64(x)
