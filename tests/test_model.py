"""Model = rigid core + effects: assembly by Lagrange's equations against hand-derived forms."""

import jax.numpy as jnp
import numpy as np
import pytest

import jflex
from jflex.effects import AbstractEffect
from _references import random_inertia_params


class _SpringMotor(AbstractEffect):
    """A motor coordinate per joint, rotor inertia b and a spring k to the link (Spong's model)."""

    b: jnp.ndarray
    k: jnp.ndarray

    def coord_names(self, robot):
        return tuple(f"theta_{j}" for j in robot.joint_names)

    def kinetic_energy(self, robot, slots, x, xd):
        return 0.5 * jnp.sum(self.b * xd[slots.coords] ** 2)

    def potential_energy(self, robot, slots, x):
        return 0.5 * jnp.sum(self.k * (x[slots.coords] - x[: slots.n]) ** 2)

    def actuation(self, robot, slots, B):
        n = slots.n
        return jnp.zeros_like(B).at[slots.coords, :].set(jnp.eye(n))


def _robot(seed=0, n=3):
    rng = np.random.default_rng(seed)
    table = np.column_stack([rng.uniform(-2, 2, n), rng.uniform(-0.5, 0.5, n), rng.uniform(-0.5, 0.5, n), np.zeros(n)])
    return jflex.from_dh(table, inertias=[random_inertia_params(rng) for _ in range(n)]), rng


def test_rigid_model_equals_rigid_algorithms():
    robot, rng = _robot()
    model = jflex.Model(robot)
    q, qd, tau = rng.normal(size=(3, robot.nq))
    np.testing.assert_allclose(jflex.mass_matrix(model, q), jflex.crba(robot, q), atol=1e-12)
    xdd, zd = jflex.model_forward_dynamics(model, 0.0, q, qd, jnp.zeros(0), tau)
    np.testing.assert_allclose(xdd, jflex.forward_dynamics(robot, q, qd, tau), atol=1e-9)
    K = jflex.linearize(model, q).K
    np.testing.assert_allclose(K, jflex.gravity_stiffness(robot, q), atol=1e-10)


def test_spong_model_assembled_from_energies():
    robot, rng = _robot(1)
    n = robot.nq
    b, k = rng.uniform(0.5, 2.0, n), rng.uniform(100.0, 1000.0, n)
    model = jflex.Model(robot, [_SpringMotor(jnp.asarray(b), jnp.asarray(k))])
    assert model.layout.coord_names[n:] == tuple(f"theta_{j}" for j in robot.joint_names)
    q, th, qd, thd, u = rng.normal(size=(5, n))
    x, xd = jnp.concatenate([q, th]), jnp.concatenate([qd, thd])
    xdd, _ = jflex.model_forward_dynamics(model, 0.0, x, xd, jnp.zeros(0), u)
    # Spong: M(q) qdd + h(q, qd) = K (th - q);  B thdd + K (th - q) = u
    qdd_ref = jflex.forward_dynamics(robot, q, qd, k * (th - q))
    thdd_ref = (u - k * (th - q)) / b
    np.testing.assert_allclose(xdd[:n], qdd_ref, atol=1e-9)
    np.testing.assert_allclose(xdd[n:], thdd_ref, atol=1e-9)
    # linearisation with the motors held: K0 = K + dG/dq on the link side
    lin = jflex.linearize(model, x, hold=model.layout.coord_names[n:])
    np.testing.assert_allclose(lin.K, np.diag(k) + jflex.gravity_stiffness(robot, q), atol=1e-9)
    np.testing.assert_allclose(lin.M, jflex.crba(robot, q), atol=1e-12)


def test_model_rejects_wrong_state_length():
    robot, _ = _robot()
    with pytest.raises(jflex.ShapeError, match="x must have shape"):
        jflex.mass_matrix(jflex.Model(robot), jnp.zeros(robot.nq + 1))


def test_linearisation_leaves_out_coulomb_friction():
    """At rest Coulomb friction sticks: it must not appear as a steep viscous term in C."""
    robot, rng = _robot(2)
    n = robot.nq
    fj = jflex.effects.FlexibleJoints(np.full(n, 1e4), np.full(n, 5.0), np.full(n, 0.1),
                                      link_coulomb=np.full(n, 20.0), motor_coulomb=np.full(n, 20.0))
    model = jflex.Model(robot, [fj])
    lin = jflex.linearize(model, jnp.zeros(2 * n), hold=model.layout.coord_names[n:])
    np.testing.assert_allclose(lin.C, 5.0 * np.eye(n), atol=1e-9)
