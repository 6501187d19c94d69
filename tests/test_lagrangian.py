"""The autodiff Lagrangian against RNEA / CRBA (an independent check of both), and the rigid
limit of an assumed-mode link against RNEA / CRBA of the same link as a rigid rod."""

import jax
import jax.numpy as jnp
import numpy as np

import jflex
from jflex.effects import FlexibleLink

RTOL = 1e-10


def _arm(inertia2, gravity=(0.0, -9.81, 0.0)):
    """Planar 2R arm (seed 004 geometry): link 1 of length 0.3 m, link 2 clamped at joint 2."""
    I1 = [0.5, 0.075, 0.0, 0.0, 0.0, 0.0, 0.02, 0.0, 0.0, 0.02]
    return jflex.make_robot(
        joint_names=["j1", "j2"], link_names=["l1", "l2"], parents=[-1, 0], joint_types=["revolute", "revolute"],
        placement_R=np.stack([np.eye(3)] * 2), placement_p=np.array([[0, 0, 0], [0.3, 0, 0.0]]),
        axis=[[0, 0, 1.0], [0, 0, 1.0]], inertia=np.array([I1, inertia2]), gravity=gravity,
    )


def test_lagrangian_of_rigid_robot_equals_crba_and_rnea():
    rng = np.random.default_rng(0)
    robot = jflex.from_dh(
        [[0, 0, 0.3, 0], [-np.pi / 2, 0.1, 0, 0], [0, 0.4, 0.05, 0]],
        inertias=[{"mass": 2.0 + i, "com": rng.normal(size=3) * 0.1, "inertia": [0.1, 0.01, 0.2, 0.0, 0.02, 0.15]} for i in range(3)],
    )
    T = lambda q, qd: jflex.kinetic_energy(robot, q, qd)
    V = lambda q: jflex.potential_energy(robot, q)
    lag = jax.jit(lambda q, qd: (jflex.lagrangian_mass_matrix(T, q), jflex.lagrangian_bias(T, V, q, qd)))
    ref = jax.jit(lambda q, qd: (jflex.crba(robot, q), jflex.rnea(robot, q, qd, jnp.zeros(3))))
    for _ in range(3):
        q, qd = rng.normal(size=3), rng.normal(size=3)
        (M, h), (Mr, hr) = lag(q, qd), ref(q, qd)
        np.testing.assert_allclose(M, Mr, rtol=RTOL, atol=1e-12)
        np.testing.assert_allclose(h, hr, rtol=RTOL, atol=1e-12)


def test_flexible_link_rigid_limit_matches_rigid_rod():
    mu, L, EI = 0.157, 0.8, 0.349
    beam = jflex.make_beam(L, mu, EI, 2)
    hub = [0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 1e-3, 0.0, 0.0, 1e-3]  # what the robot's link 2 keeps
    model = jflex.Model(_arm(hub), [FlexibleLink("l2", beam, root=(0.02, 0.0, 0.0))])
    # the same beam as a rigid rod from x = 0.02 to 0.02 + L, added to link 2 (thin: only Izz, Iyy)
    m, a, b = mu * L, 0.02, 0.02 + L
    Izz = mu * (b**3 - a**3) / 3
    rod = np.array([m, m * (a + b) / 2, 0, 0, 0, 0, Izz, 0, 0, Izz])
    rigid = _arm(np.array(hub) + rod)
    terms = jax.jit(lambda x, xd: (jflex.mass_matrix(model, x), jflex.bias_forces(model, 0.0, x, xd, jnp.zeros(0))))
    rng = np.random.default_rng(1)
    for _ in range(3):
        q, qd = rng.normal(size=2), rng.normal(size=2)
        x = jnp.concatenate([q, jnp.zeros(2)])
        xd = jnp.concatenate([qd, jnp.zeros(2)])
        M, h = terms(x, xd)
        np.testing.assert_allclose(M[:2, :2], jflex.crba(rigid, q), rtol=1e-9)
        np.testing.assert_allclose(h[:2], jflex.rnea(rigid, q, qd, np.zeros(2)), rtol=1e-9, atol=1e-12)
