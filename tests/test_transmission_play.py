"""Play (backlash) inside a compliant transmission: ``FlexibleJoints(..., play=b)``, the spring
torque ``k dz(theta - q, b) + c (theta_dot - q_dot)`` with a smooth dead zone (issue 13, item 4).
Closed forms on a motor-link pair, energy balance of a free bounce in the gap, and play 0 as the
plain spring bit for bit."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jflex
from jflex.effects import FlexibleJoints
from jflex.effects._flexible_joint import smooth_dead_zone

K, IM = 2e3, 2e-3  # [N m/rad], [kg m^2] motor side after the gear
_fd = eqx.filter_jit(jflex.model_forward_dynamics)  # one compile for the pair's tests (same structure)


def pair(gravity=(0.0, 0.0, -9.81)):
    """One link turning about z (gravity along the axis: no gravity torque)."""
    inert = [{"mass": 3.0, "com": [0.25, 0.02, 0.0], "inertia": [0.1, 0.0, 0.2, 0.0, 0.0, 0.25]}]
    return jflex.from_dh([[0.0, 0.0, 0.0, 0.0]], tool=[0.0, 0.5, 0.0, 0.0], inertias=inert, gravity=gravity)


def test_no_play_is_todays_spring_and_play_zero_equals_it():
    """The default (``play=None``) is today's model: same leaves, same code path, so the same
    compiled program bit for bit. ``play=0`` adds exact zeros to the spring's energy and forces;
    compiled, they agree with the plain spring to the last bits (XLA fuses the larger graph
    differently: a few ulps)."""
    robot = jflex.from_dh([[0.0, 0.0, 0.0, 0.0], [0.0, 0.5, 0.0, 0.0]], tool=[0.0, 0.5, 0.0, 0.0],
                          inertias=[{"mass": 3.0, "com": [0.25, 0.02, 0.0], "inertia": [0.1, 0.0, 0.2, 0.0, 0.0, 0.25]}] * 2,
                          gravity=(0.0, -9.81, 0.0))
    kw = dict(rotor_inertia=[2e-3, 1e-3], gear_ratio=[1.0, 1.0], joints=[0, 1], coupling=False)
    fj = FlexibleJoints([K, 1.5 * K], [0.3, 0.2], **kw)
    assert fj.play is None and fj.play_smoothing is None
    assert len(jax.tree_util.tree_leaves(fj)) == 9  # the leaves it had before play existed
    plain = jflex.Model(robot, [fj])
    zero = jflex.Model(robot, [FlexibleJoints([K, 1.5 * K], [0.3, 0.2], play=[0.0, 0.0], **kw)])
    fd = eqx.filter_jit(jflex.model_forward_dynamics)
    rng = np.random.default_rng(0)
    for _ in range(3):
        x, xd, u = rng.normal(size=4), rng.normal(size=4), rng.normal(size=2)
        a, _ = fd(plain, 0.0, x, xd, jnp.zeros(0), u)
        b, _ = fd(zero, 0.0, x, xd, jnp.zeros(0), u)
        assert np.allclose(a, b, rtol=1e-13, atol=0)


def test_static_deflection_is_play_plus_torque_over_stiffness():
    """At rest the motor holds a load torque tau through the transmission at deflection b + tau / k."""
    b, eps = 0.01, 1e-5
    model = jflex.Model(pair(), [FlexibleJoints([K], [0.0], [IM], play=[b], play_smoothing=eps, coupling=False)])
    fj, slots = model.effects[0], model.layout.slots[0]
    z = np.zeros(2)
    for tau in (5.0, -3.0, 0.4):
        d = np.sign(tau) * b + tau / K
        x = np.array([0.2, 0.2 + d])
        tol = K * eps**2 / (2 * abs(tau / K))  # the rounded corner's share (see FlexibleJoints.play_smoothing)
        assert abs(float(fj.spring_torque(model.rigid, slots, x, z)[0]) - tau) < tol
    # the motor applies tau: it stays put, the link takes tau through the transmission
    J = float(jflex.crba(model.rigid, x[:1])[0, 0])
    xdd, _ = _fd(model, 0.0, x, z, jnp.zeros(0), np.array([tau]))
    assert abs(float(xdd[0]) * J - tau) < tol and abs(float(xdd[1]) * IM) < tol


def test_inside_the_gap_the_link_is_free():
    b, eps = 0.01, 1e-5
    model = jflex.Model(pair(), [FlexibleJoints([K], [0.0], [IM], play=[b], play_smoothing=eps, coupling=False)])
    fd = _fd
    J = float(jflex.crba(model.rigid, np.zeros(1))[0, 0])
    for d in (-0.009, -0.004, 0.0, 0.006, 0.009):
        qdd, _ = fd(model, 0.0, np.array([0.1, 0.1 + d]), np.array([0.5, -0.3]), jnp.zeros(0),
                                              np.zeros(1))
        # the spring's torque at the edge of the gap would be k * (a few eps): here it is ~k eps^2 / b
        assert abs(float(qdd[0])) * J < 1e-5 * K * b
        assert abs(float(qdd[1])) * IM < 1e-5 * K * b
    # beyond the gap: the plain spring shifted by b
    d = 0.03
    qdd, _ = fd(model, 0.0, np.array([0.1, 0.1 + d]), np.zeros(2), jnp.zeros(0), np.zeros(1))
    assert float(qdd[0]) * J == pytest.approx(K * (d - b), rel=1e-6)
    assert float(qdd[1]) * IM == pytest.approx(-K * (d - b), rel=1e-6)
    # the dead zone is monotone, odd, and the identity without play
    x = np.linspace(-0.05, 0.05, 2001)
    y = np.asarray(smooth_dead_zone(jnp.asarray(x), b, eps))
    assert np.all(np.diff(y) > 0) and np.allclose(y, -y[::-1], atol=1e-15)
    assert np.array_equal(np.asarray(smooth_dead_zone(jnp.asarray(x), 0.0, eps)), x)
    assert np.allclose(y, np.sign(x) * np.maximum(np.abs(x) - b, 0.0), atol=eps)


def test_energy_is_conserved_through_the_contacts():
    """No damping: the link and motor bounce across the gap (several contacts); the total energy
    (kinetic + the spring's dead-zone energy) stays constant, and the play slows the oscillation."""
    b = 0.02
    model = jflex.Model(pair(), [FlexibleJoints([K], [0.0], [IM], play=[b], play_smoothing=1e-4, coupling=False)])
    ts = np.linspace(0.0, 0.5, 51)
    r = jflex.simulate(model, ts, np.array([0.0, 0.0]), np.array([0.0, 3.0]), outputs=("energy", "x"), rtol=1e-10,
                       atol=1e-12, max_steps=200_000)
    E = np.asarray(r.outputs["energy"])
    assert E[0] == pytest.approx(0.5 * IM * 9.0, rel=1e-12)
    assert np.max(np.abs(E - E[0])) < 1e-7 * E[0]
    d = np.asarray(r.outputs["x"])[:, 1] - np.asarray(r.outputs["x"])[:, 0]
    assert d.max() > b and d.min() < -b  # it crossed the gap both ways


def test_bad_play_raises_clear_errors():
    with pytest.raises(jflex.ParameterError, match=r"FlexibleJoints\.play"):
        FlexibleJoints([K, K], play=[0.01, -0.001])
    with pytest.raises(jflex.ParameterError, match=r"FlexibleJoints\.play_smoothing"):
        FlexibleJoints([K], play=[0.01], play_smoothing=0.0)
    with pytest.raises(jflex.ShapeError, match=r"FlexibleJoints\.play"):
        FlexibleJoints(np.diag([K, K]), play=[0.01, 0.01])
    with pytest.raises(jflex.ShapeError, match=r"FlexibleJoints\.play"):
        FlexibleJoints([K, K], play=[0.01, 0.01, 0.0])
