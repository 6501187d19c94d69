"""Identities between the rigid-body algorithms on random states, independent of any peer."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jflex
from _references import random_inertia_params

TOL = 1e-10


def random_robot(seed, n=5):
    rng = np.random.default_rng(seed)
    table = np.column_stack(
        [rng.uniform(-np.pi, np.pi, n), rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(-np.pi, np.pi, n)]
    )
    types = list(rng.choice(["revolute", "prismatic"], n, p=[0.7, 0.3]))
    return jflex.from_dh(table, joint_types=types, inertias=[random_inertia_params(rng) for _ in range(n)], tool=[0, 0.3, 0.1, 0]), rng


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_inverse_dynamics_identities(seed):
    robot, rng = random_robot(seed)
    q, qd, qdd = rng.normal(size=(3, robot.nq))
    M = jflex.crba(robot, q)
    h = jflex.nonlinear_effects(robot, q, qd)
    tau = jflex.rnea(robot, q, qd, qdd)
    np.testing.assert_allclose(tau, M @ qdd + h, atol=TOL * np.abs(tau).max())
    np.testing.assert_allclose(M, M.T, atol=1e-14)
    assert np.linalg.eigvalsh(M).min() > 0
    Y = jflex.regressor(robot, q, qd, qdd)
    np.testing.assert_allclose(Y @ robot.inertia.ravel(), tau, atol=TOL * np.abs(tau).max())
    # forward dynamics inverts inverse dynamics, both methods
    for method in ("aba", "crba"):
        np.testing.assert_allclose(jflex.forward_dynamics(robot, q, qd, tau, method=method), qdd, atol=1e-9)
    # M is the Hessian of the kinetic energy in qd
    np.testing.assert_allclose(jax.hessian(lambda v: jflex.kinetic_energy(robot, q, v))(qd), M, atol=1e-10)
    # g is the gradient of the potential energy
    np.testing.assert_allclose(jax.grad(lambda x: jflex.potential_energy(robot, x))(q), jflex.gravity(robot, q), atol=1e-10)


@pytest.mark.parametrize("seed", [3, 4])
def test_power_balance(seed):
    """d(T + V)/dt = qd . tau along the motion that tau produces."""
    robot, rng = random_robot(seed)
    q, qd, tau = rng.normal(size=(3, robot.nq))
    qdd = jflex.forward_dynamics(robot, q, qd, tau)
    E = lambda q_, qd_: jflex.kinetic_energy(robot, q_, qd_) + jflex.potential_energy(robot, q_)
    _, dE = jax.jvp(E, (jnp.asarray(q), jnp.asarray(qd)), (jnp.asarray(qd), qdd))
    np.testing.assert_allclose(dE, qd @ tau, rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("seed", [5, 6])
def test_jacobian_equals_autodiff_of_kinematics(seed):
    robot, rng = random_robot(seed)
    q = jnp.asarray(rng.normal(size=robot.nq))
    T = lambda x: jflex.frame_placement(robot, x, "tool")
    dT = jax.jacfwd(T)(q)  # (4, 4, n)
    R = T(q)[:3, :3]
    J = jflex.jacobian(robot, q, "tool")
    np.testing.assert_allclose(J[:3], dT[:3, 3, :], atol=1e-12)
    # angular part: skew(omega) = dR R^T
    for j in range(robot.nq):
        W = dT[:3, :3, j] @ R.T
        np.testing.assert_allclose(J[3:, j], [W[2, 1], W[0, 2], W[1, 0]], atol=1e-12)
    Jl = jflex.jacobian(robot, q, "tool", reference="local")
    np.testing.assert_allclose(Jl[:3], R.T @ J[:3], atol=1e-12)


def test_algorithms_vmap_and_jit():
    robot, rng = random_robot(7)
    q, qd, qdd = rng.normal(size=(3, 16, robot.nq))
    batched = jax.jit(jax.vmap(lambda a, b, c: jflex.rnea(robot, a, b, c)))(q, qd, qdd)
    for k in range(16):
        np.testing.assert_allclose(batched[k], jflex.rnea(robot, q[k], qd[k], qdd[k]), atol=1e-12)


def test_gradient_reaches_every_physical_number():
    """Inertias, placements and gravity are leaves: d tau / d(leaf) against central differences."""
    robot, rng = random_robot(8, n=3)
    q, qd, qdd = rng.normal(size=(3, robot.nq))
    f = lambda r: jnp.sum(jflex.rnea(r, q, qd, qdd) ** 2)
    g = jax.grad(f)(robot)
    for field in ("inertia", "placement_p", "gravity"):
        x0 = np.asarray(getattr(robot, field))
        d = rng.normal(size=x0.shape)
        eps = 1e-6
        fp = f(robot.replace(**{field: x0 + eps * d}))
        fm = f(robot.replace(**{field: x0 - eps * d}))
        np.testing.assert_allclose(np.sum(np.asarray(getattr(g, field)) * d), (fp - fm) / (2 * eps), rtol=1e-6)


@pytest.mark.parametrize("algo", ["crba", "aba", "rnea"])
def test_traced_robot_matches_constant_robot(algo):
    """With the robot traced (an argument of jit, or differentiated), the kernels take their
    general paths (no trace-time folding): same numbers, and d/d(axis, placement_R) against
    central differences."""
    robot = jflex.load_robot("ur5")
    rng = np.random.default_rng(11)
    q, qd, x = rng.normal(size=(3, robot.nq))
    fn = {
        "crba": lambda r: jflex.crba(r, q),
        "aba": lambda r: jflex.aba(r, q, qd, x),
        "rnea": lambda r: jflex.rnea(r, q, qd, x),
    }[algo]
    np.testing.assert_allclose(jax.jit(fn)(robot), fn(robot), rtol=1e-12, atol=1e-12)
    f = lambda r: jnp.sum(fn(r) ** 2)
    g = jax.grad(f)(robot)
    for field in ("axis", "placement_R", "inertia"):
        x0 = np.asarray(getattr(robot, field))
        d = rng.normal(size=x0.shape)
        eps = 1e-6
        fd = (f(robot.replace(**{field: x0 + eps * d})) - f(robot.replace(**{field: x0 - eps * d}))) / (2 * eps)
        np.testing.assert_allclose(np.sum(np.asarray(getattr(g, field)) * d), fd, rtol=1e-6, atol=1e-9)
