"""The direct-form FRF's custom JVP (jflex.linear._frf._direct): same values as the plain inverse,
derivatives equal to forward-mode AD through the inverse, to reverse mode and to finite
differences, for every input it can be differentiated in (M, C, K, the output map T, the
frequencies, a frequency-dependent effect term)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jflex
from jflex.effects import FlexibleJoints, Hysteretic, Spring
from jflex.linear import frf_matrices
from jflex.linear._common import linearization, tool_jacobian

OMEGA = 2 * np.pi * np.linspace(5.0, 100.0, 9)
K0 = np.array([2.0e4, 2.0e4, 1.0e4, 2.0e3, 2.0e3, 1.0e3])
C0 = np.array([10.0, 10.0, 5.0, 1.0, 1.0, 0.5])
I0 = np.array([2e-4, 3e-4, 1e-4, 1e-5, 1e-5, 1e-6])
Q = np.array([0.3, -1.1, 1.4, -1.5, 0.9, 0.2])


def _reference_frf(model, q, omega, frame, components="full"):
    """The implementation before the custom JVP: one inverse per frequency, differentiated by JAX."""
    x0, lin = linearization(model, q, ())
    T = None if frame is None else tool_jacobian(model, x0, lin.keep, frame, "local_world_aligned", components)
    idx = jnp.array(lin.keep, dtype=int)
    r, lay = model.rigid, model.layout

    def one(w):
        D = lin.K - w**2 * lin.M + 1j * w * lin.C
        for e, s in zip(model.effects, lay.slots):
            extra = e.dynamic_stiffness(r, s, x0, w)
            if extra is not None:
                D = D + extra[jnp.ix_(idx, idx)]
        G = jnp.linalg.inv(D)
        return G if T is None else T @ G @ T.T

    return jax.vmap(one)(omega)


def _ur5(u, hysteretic=False):
    K, C, I = jnp.exp(u[:6]), jnp.exp(u[6:12]), jnp.exp(u[12:18])
    eff = [FlexibleJoints(K, C, rotor_inertia=I, gear_ratio=[100.0] * 6, coupling=False)]
    if not hysteretic:
        return jflex.Model(jflex.load_robot("ur5"), eff)
    # a structurally damped spring on joint 2 (a frequency-dependent term), its stiffness and loss
    # factor set after construction (the constructor checks concrete values)
    model = jflex.Model(jflex.load_robot("ur5"), eff + [Spring([1], [500.0], Hysteretic(eta=0.05))])
    return eqx.tree_at(lambda m: (m.effects[1].stiffness, m.effects[1].law.eta), model,
                       (jnp.exp(u[18]).reshape(1, 1), jnp.exp(u[19])))


U0 = np.log(np.concatenate([K0, C0, I0]))
U0H = np.concatenate([U0, np.log([500.0, 0.05])])


def _split(H):
    return jnp.stack([H.real, H.imag])


def _pair(hysteretic, frame):
    def new(u):
        return _split(jflex.frf(_ur5(u, hysteretic), Q, OMEGA, frame=frame, components="full"))

    def ref(u):
        return _split(_reference_frf(_ur5(u, hysteretic), Q, OMEGA, frame))

    return new, ref


@pytest.mark.parametrize("hysteretic, frame", [(False, "tool0"), (True, None)], ids=["tool-viscous", "joint_space-hysteretic"])
def test_values_and_forward_jacobian_match_the_plain_inverse(hysteretic, frame):
    u = jnp.asarray(U0H if hysteretic else U0)
    new, ref = _pair(hysteretic, frame)
    Hn, Hr = np.asarray(jax.jit(new)(u)), np.asarray(jax.jit(ref)(u))
    scale = np.abs(Hr).max()
    np.testing.assert_allclose(Hn, Hr, rtol=0, atol=1e-12 * scale)
    Jn, Jr = np.asarray(jax.jit(jax.jacfwd(new))(u)), np.asarray(jax.jit(jax.jacfwd(ref))(u))
    np.testing.assert_allclose(Jn, Jr, rtol=0, atol=1e-10 * np.abs(Jr).max())
    # every parameter is seen (no tangent silently dropped)
    assert (np.abs(Jn).reshape(-1, u.shape[0]).max(axis=0) > 1e-8 * np.abs(Jn).max()).all()


def test_reverse_mode_and_finite_differences():
    u = jnp.asarray(U0H)
    new, _ = _pair(True, "tool0")
    Jf = np.asarray(jax.jit(jax.jacfwd(new))(u))
    Jb = np.asarray(jax.jit(jax.jacrev(new))(u))
    np.testing.assert_allclose(Jb, Jf, rtol=0, atol=1e-10 * np.abs(Jf).max())
    f = jax.jit(new)
    for k in (0, 7, 14, 19):  # a stiffness, a damping, a rotor inertia, the hysteretic loss factor
        h = 1e-4  # log-parameters; the FRF carries ~1e-12 relative round-off near resonances
        e = jnp.zeros_like(u).at[k].set(h)
        fd = (np.asarray(f(u + e)) - np.asarray(f(u - e))) / (2 * h)
        np.testing.assert_allclose(Jf[..., k], fd, rtol=0, atol=1e-6 * np.abs(fd).max() + 1e-7 * np.abs(Jf).max())


def _matrices(n, seed=0):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    M = A @ A.T + n * np.eye(n)
    A = rng.normal(size=(n, n))
    K = 400.0 * (A @ A.T + n * np.eye(n))
    C = 0.01 * K + 0.1 * rng.normal(size=(n, n))  # not symmetric: the transposed solve matters
    T = rng.normal(size=(2, n))
    return M, C, K, T


def _reference_matrices(M, C, K, w, T):
    G = jax.vmap(lambda w: jnp.linalg.inv(K - w**2 * M + 1j * w * C))(w)
    return G if T is None else jnp.einsum("ai,fij,bj->fab", T, G, T)


@pytest.mark.parametrize("n", [2, 3, 5], ids=["adjugate2", "adjugate3", "lu5"])
@pytest.mark.parametrize("with_T", [True, False], ids=["T", "noT"])
def test_matrix_level_derivatives_in_every_input(n, with_T):
    """frf_matrices differentiated in M, C, K, T and the frequencies at once against the plain inverse."""
    M, C, K, T = _matrices(n)
    w = jnp.linspace(1.0, 40.0, 7)
    T = T if with_T else None

    def pack(M, C, K, w, T):
        return [M, C, K, w] + ([] if T is None else [T])

    def new(args):
        H = frf_matrices(*args[:4], T=args[4] if with_T else None)
        return _split(H)

    def ref(args):
        return _split(_reference_matrices(*args[:4], args[4] if with_T else None))

    args = [jnp.asarray(a) for a in pack(M, C, K, w, T)]
    np.testing.assert_allclose(np.asarray(new(args)), np.asarray(ref(args)), rtol=0, atol=1e-12 * np.abs(ref(args)).max())
    Jn, Jr = jax.jacfwd(new)(args), jax.jacfwd(ref)(args)
    for a, b in zip(Jn, Jr):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=0, atol=1e-10 * np.abs(np.asarray(b)).max())
    for a, b in zip(jax.jacrev(new)(args), Jr):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=0, atol=1e-10 * np.abs(np.asarray(b)).max())


def test_second_derivatives_and_vmap():
    """Higher-order AD goes through the JVP rule itself; a posture batch (vmap) is unchanged."""
    M, C, K, T = _matrices(4, seed=3)
    w = jnp.linspace(1.0, 40.0, 5)

    def f(s, impl):
        return jnp.sum(jnp.abs(impl(M * (1 + s[0]), C * (1 + s[1]), K * (1 + s[2]), w, T)) ** 2)

    new = lambda *a: frf_matrices(*a[:4], T=a[4])
    s = jnp.asarray([0.1, -0.2, 0.05])
    np.testing.assert_allclose(jax.hessian(lambda s: f(s, new))(s), jax.hessian(lambda s: f(s, _reference_matrices))(s),
                               rtol=1e-9)
    Ks = jnp.stack([K, 1.3 * K])
    Hb = jax.vmap(lambda K: frf_matrices(M, C, K, w, T=T))(Ks)
    for i in range(2):
        np.testing.assert_array_equal(np.asarray(Hb[i]), np.asarray(frf_matrices(M, C, Ks[i], w, T=T)))
