"""The structured (sparse) exact Jacobian of FRF fits (jflex.identify.sparse_frf_residual and
fit(..., jacobian="sparse")): the same residual, a Jacobian equal to jax.jacfwd of the plain
residual (with entries, weights, a free motor side, a non-receptance kind), a pattern entry that
vanishes at the start found by the random probes (and caught at evaluation when it is not), the
same fitted minimum as the dense path, and clear errors for what it does not support.

Small on purpose (a 2-joint arm, 2 postures, 8-10 frequencies): compilation dominates."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jflex
from jflex import identify as idf
from jflex._errors import DataError, ParameterError
from jflex.effects import FlexibleJoints, Hysteretic, Spring

from _identify_helpers import STAUBLI_DH, random_inertias

K0, C0, I0 = np.array([2e5, 5e5]), np.array([300.0, 100.0]), np.array([1e-3, 2e-3])
POSTURES = np.array([[0.0, 0.5], [0.3, 1.0]])
OMEGA = 2 * np.pi * np.linspace(2.0, 60.0, 8)


def _robot():
    return jflex.from_dh(STAUBLI_DH[:2], tool=[0, 0.994, 0, 0], inertias=random_inertias(2, 3))


def _model(K, C, I, extra=()):
    return jflex.Model(_robot(), [FlexibleJoints(K, C, rotor_inertia=I, gear_ratio=[100.0] * 2, coupling=False), *extra])


class _Square(idf.AbstractTransform):
    """``p = u^2``: at ``u = 0`` every derivative of the model in this parameter vanishes, a
    non-zero pattern entry that is zero by coincidence at the start."""

    def forward(self, u):
        return u**2

    def inverse(self, p):
        return jnp.sqrt(jnp.asarray(p))


def _spec():
    return idf.ParameterSpec([idf.Free("K", lambda m: m.effects[0].stiffness, transform=idf.Log()),
                              idf.Free("C0", lambda m: m.effects[0].damping, index=(0,), transform=idf.Log()),
                              idf.Free("C1", lambda m: m.effects[0].damping, index=(1,), transform=_Square()),
                              idf.Free("I_m", lambda m: m.effects[0].rotor_inertia, transform=idf.Log())])


_CACHE = {}


def _tool_data():
    """Motor side free (hold=()), tool FRF as mobility, three of the nine entries, unequal weights."""
    if "tool" not in _CACHE:
        true = _model(K0, C0, I0)
        H = jax.jit(jax.vmap(lambda q: jflex.frf(true, q, OMEGA, hold=(), frame="tool", kind="mobility")))(jnp.asarray(POSTURES))
        _CACHE["tool"] = idf.FRFData(POSTURES, OMEGA, np.asarray(H), hold=(), frame="tool", kind="mobility",
                                     entries=[(0, 0), (1, 2), (2, 1)], weights=(2.0, 0.5))
    return _CACHE["tool"]


def _start():
    return _model(K0 * 1.3, np.array([C0[0] * 0.8, 0.0]), I0 * 1.2)  # C1 = 0: u = 0 under _Square


def test_jacobian_equals_jacfwd_of_the_plain_residual():
    data, start = _tool_data(), _start()
    spec = _spec().bind(start)
    s = idf.sparse_frf_residual(_spec(), start, data)
    # 4 entries of K_lin per joint spring, 4 of C_lin per damper, 1 of M per rotor; C1's entries are
    # zero at the start (u = 0) and found at the random probes
    assert s.entries_per_parameter == (4, 4, 4, 4, 1, 1)

    def plain(u):
        return idf.residual_vector(spec.apply(start, u), data)

    # (the residual, its Jacobian, the residual as the JVP computes it) in one program per function
    both = lambda f: jax.jit(lambda u: (f(u), *jax.jacfwd(lambda v: (f(v), f(v)), has_aux=True)(u)))
    ref, new = both(plain), both(s)
    u0 = spec.pack(start)
    u1 = (u0 + jnp.asarray(np.random.default_rng(0).normal(scale=0.2, size=u0.shape))).at[3].set(np.sqrt(C0[1]))
    for u in (u0, u1):
        (r0, J0, _), (r1, J1, r2) = (tuple(np.asarray(a) for a in f(u)) for f in (ref, new))
        np.testing.assert_array_equal(r1, r0)  # the primal is the plain residual itself
        np.testing.assert_allclose(J1, J0, rtol=0, atol=1e-9 * np.abs(J0).max())
        np.testing.assert_allclose(r2, r0, rtol=0, atol=1e-13 * np.abs(r0).max())  # the JVP's: to round-off
    assert np.abs(J1[:, 3]).max() > 1e-3 * np.abs(J1).max()  # C1's column is live away from the start


def test_an_entry_missed_by_the_pattern_raises_instead_of_a_wrong_jacobian():
    data, start = _tool_data(), _start()
    s = idf.sparse_frf_residual(_spec(), start, data, probes=0)  # only the start: C1 looks constant
    assert s.entries_per_parameter[3] == 0
    u1 = _spec().bind(start).pack(start).at[3].set(0.5)
    with pytest.raises(Exception, match="outside the sparsity pattern"):
        jax.block_until_ready(jax.jit(jax.jacfwd(s))(u1))


def test_fit_reaches_the_same_minimum_as_the_dense_path():
    """Joint-space FRFs (frame=None), motor angles held: the K and C of both joints."""
    true = _model(K0, C0, I0)
    H = np.asarray(jax.jit(jax.vmap(lambda q: jflex.frf(true, q, OMEGA, hold="actuated")))(jnp.asarray(POSTURES)))
    H = H * np.exp(0.01 * np.random.default_rng(1).normal(size=H.shape))  # a minimum with a non-zero cost
    data = idf.FRFData(POSTURES, OMEGA, H)
    spec = idf.ParameterSpec([idf.Free("K", lambda m: m.effects[0].stiffness, transform=idf.Log()),
                              idf.Free("C", lambda m: m.effects[0].damping, transform=idf.Log())])
    start = _model(K0 * [1.3, 0.8], C0 * [0.8, 1.3], I0)
    dense = idf.fit(start, spec, data, progress=False, max_steps=40)
    sparse = idf.fit(start, spec, data, progress=False, max_steps=40, jacobian="sparse")
    assert dense.result == sparse.result == "converged"
    assert dense.cost > 0 and abs(sparse.cost - dense.cost) <= 1e-10 * dense.cost
    for k in ("K", "C"):
        np.testing.assert_allclose(sparse.values[k], dense.values[k], rtol=1e-8)
        np.testing.assert_allclose(sparse.std[k], dense.std[k], rtol=1e-6)
    np.testing.assert_allclose(sparse.singular_values, dense.singular_values, rtol=1e-8)


def test_what_it_does_not_support_raises_clearly():
    data, start = _tool_data(), _start()
    torque = idf.TorqueData(*(np.zeros((4, 2)) + i for i in range(4)))
    with pytest.raises(DataError, match="FRFData only, got TorqueData"):
        idf.sparse_frf_residual(_spec(), start, torque)
    with pytest.raises(DataError, match="applies to FRFData"):
        idf.fit(start, _spec(), torque, jacobian="sparse", progress=False)
    with pytest.raises(ParameterError, match="'dense' or 'sparse'"):
        idf.fit(start, _spec(), data, jacobian="structured", progress=False)
    # a free parameter on the data's own arrays
    on_data = idf.ParameterSpec([idf.Free("w", lambda d: d[0].omega, on="data")])
    with pytest.raises(ParameterError, match="field 'omega'"):
        idf.sparse_frf_residual(on_data, start, data)
    # a frequency-dependent (hysteretic) stiffness is not carried
    hyst = _model(K0, C0, I0, [Spring([1], [500.0], Hysteretic(eta=0.05))])
    with pytest.raises(ParameterError, match="frequency-dependent"):
        idf.sparse_frf_residual(_spec(), hyst, data)
    # the tool Jacobian moves with a free tool offset
    tool = idf.ParameterSpec(list(_spec().frees) + [idf.Free("tool_y", lambda m: m.robot.frame_p, index=(0, 1))])
    with pytest.raises(ParameterError, match=r"tool Jacobian \(FRFData field 'frame' = 'tool'\) depends on .*tool_y"):
        idf.sparse_frf_residual(tool, start, data)
