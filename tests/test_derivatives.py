"""Analytic derivatives of RNEA and ABA against Pinocchio's computeRNEADerivatives /
computeABADerivatives (UR5 and Panda URDFs of example-robot-data, the Panda with its two prismatic
fingers: a branching tree) and against forward-mode AD of jflex.rnea / jflex.aba on DH robots
with prismatic joints and tilted gravity. One named tolerance: 1e-9 relative to the largest entry."""

import jax
import numpy as np
import pytest

import jflex
from _references import pin, random_inertia_params
from jflex._dynamics import _aba, _rnea

RTOL = 1e-9


def close(a, b, rtol=RTOL):
    a, b = np.asarray(a), np.asarray(b).reshape(np.shape(a))
    np.testing.assert_allclose(a, b, rtol=0, atol=rtol * max(1.0, np.abs(b).max()))


def _urdf_pair(name):
    if pin is None or name not in jflex.available_robots():
        pytest.skip("needs pinocchio and example-robot-data")
    from jflex._config import _example_robot_urdf

    path = str(_example_robot_urdf(name))
    robot = jflex.load_urdf(path, mimic="independent")  # the Panda's fingers, as Pinocchio loads them
    model = pin.buildModelFromUrdf(path)
    assert robot.joint_names == tuple(model.names[1:])
    return robot, model


def _state(robot, rng):
    lo = np.where(np.isfinite(robot.lower), robot.lower, -np.pi)
    hi = np.where(np.isfinite(robot.upper), robot.upper, np.pi)
    n = robot.nq
    return rng.uniform(lo, hi), rng.normal(size=n), rng.normal(size=n), rng.normal(size=(n, 6))


@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_rnea_and_aba_derivatives_match_pinocchio(name):
    robot, model = _urdf_pair(name)
    data = model.createData()
    rng = np.random.default_rng(3)
    for _ in range(2):
        q, qd, qdd, fext = _state(robot, rng)
        pin_f = [pin.Force.Zero()] + [pin.Force(f[:3], f[3:]) for f in fext]
        for f, pf in ((None, ()), (fext, (pin_f,))):
            ours = jflex.rnea_derivatives(robot, q, qd, qdd, f_ext=f)
            ref = pin.computeRNEADerivatives(model, data, q, qd, qdd, *pf)
            for a, b in zip(ours, ref):
                close(a, b)
            tau = pin.rnea(model, data, q, qd, qdd, *pf)
            ours = jflex.aba_derivatives(robot, q, qd, tau, f_ext=f)
            ref = pin.computeABADerivatives(model, data, q, qd, tau, *pf)
            for a, b in zip(ours, ref):
                close(a, b)


def _dh_robot(seed, n=5):
    rng = np.random.default_rng(seed)
    table = np.column_stack(
        [rng.uniform(-np.pi, np.pi, n), rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(-np.pi, np.pi, n)]
    )
    types = ["revolute", "prismatic", "revolute", "prismatic", "revolute"][:n]
    robot = jflex.from_dh(table, joint_types=types, inertias=[random_inertia_params(rng) for _ in range(n)],
                          gravity=[1.0, -2.0, -9.0])
    return robot, rng


@pytest.mark.parametrize("seed", [0, 1])
def test_derivatives_match_forward_mode_ad(seed):
    robot, rng = _dh_robot(seed)
    n = robot.nq
    q, qd, qdd = rng.normal(size=(3, n))
    fext = rng.normal(size=(n, 6))
    for f in (None, fext):
        # forward mode through the traversal (the public rnea's own JVP is the analytic kernel)
        ad = jax.jacfwd(lambda *x: _rnea(robot, *x, f, "rnea"), argnums=(0, 1, 2))(q, qd, qdd)
        for a, b in zip(jflex.rnea_derivatives(robot, q, qd, qdd, f_ext=f), ad):
            close(a, b)
        tau = rng.normal(size=n)
        ad = jax.jacfwd(lambda *x: jflex.aba(robot, *x, f_ext=f), argnums=(0, 1, 2))(q, qd, tau)
        for a, b in zip(jflex.aba_derivatives(robot, q, qd, tau, f_ext=f), ad):
            close(a, b)


def test_custom_jvps_equal_forward_mode_through_the_traversal():
    """jflex.rnea's and jflex.aba's analytic JVPs give what plain AD through the traversal gives, in every mode
    (jvp, jacfwd, jacrev, second order) and for tangents it hands back to plain forward mode
    (the robot's inertial parameters, external wrenches)."""
    robot, rng = _dh_robot(5, n=3)
    n = robot.nq
    x = tuple(rng.normal(size=(3, n)))
    fext = rng.normal(size=(n, 6))
    ours = lambda *a: jflex.rnea(robot, *a)
    plain = lambda *a: _rnea(robot, *a, None, "rnea")
    t = tuple(rng.normal(size=(3, n)))
    close(jax.jvp(ours, x, t)[1], jax.jvp(plain, x, t)[1])
    for mode in (jax.jacfwd, jax.jacrev):
        for a, b in zip(mode(ours, argnums=(0, 1, 2))(*x), jax.jacfwd(plain, argnums=(0, 1, 2))(*x)):
            close(a, b)
    close(jax.hessian(lambda q: ours(q, *x[1:]) @ x[2])(x[0]), jax.hessian(lambda q: plain(q, *x[1:]) @ x[2])(x[0]), 1e-8)
    by_inertia = lambda fn: jax.jacfwd(lambda I: fn(robot.replace(inertia=I), *x))(robot.inertia)
    close(by_inertia(jflex.rnea), by_inertia(lambda r, *a: _rnea(r, *a, None, "rnea")))
    close(jax.jacfwd(lambda f: jflex.rnea(robot, *x, f_ext=f))(fext), jax.jacfwd(lambda f: _rnea(robot, *x, f, "rnea"))(fext))
    # a robot traced by jit (its arrays unknown while the kernels trace) takes plain forward mode
    traced = jax.jit(lambda r, q, qd, qdd: jax.jacfwd(lambda q_: jflex.rnea(r, q_, qd, qdd))(q))(robot, *x)
    close(traced, jax.jacfwd(plain)(*x))
    # aba likewise (its JVP: aba_derivatives)
    ours = lambda *a: jflex.aba(robot, *a)
    plain = lambda *a: _aba(robot, *a, None, "aba")
    close(jax.jvp(ours, x, t)[1], jax.jvp(plain, x, t)[1], 1e-8)
    for mode in (jax.jacfwd, jax.jacrev):
        for a, b in zip(mode(ours, argnums=(0, 1, 2))(*x), jax.jacfwd(plain, argnums=(0, 1, 2))(*x)):
            close(a, b, 1e-8)
    close(by_inertia(jflex.aba), by_inertia(lambda r, *a: _aba(r, *a, None, "aba")), 1e-8)


def test_compiled_batch_matches_single_states():
    """The compiled, batched kernels (what the benchmark times: jit(vmap), run-time fences) give
    the per-state results, which the tests above check against the references."""
    robot, rng = _dh_robot(2, n=3)
    q, qd, qdd = rng.normal(size=(3, 4, robot.nq))
    for fn in (jflex.rnea_derivatives, jflex.aba_derivatives):
        batch = jax.jit(jax.vmap(lambda *x: fn(robot, *x)))(q, qd, qdd)
        for k in range(4):
            for a, b in zip(batch, fn(robot, q[k], qd[k], qdd[k])):
                close(a[k], b, rtol=1e-12)


def test_bad_input_is_named():
    robot, rng = _dh_robot(4, n=3)
    q = rng.normal(size=3)
    with pytest.raises(jflex.DataError, match="rnea_derivatives: qd"):
        jflex.rnea_derivatives(robot, q, np.array([0.0, np.nan, 0.0]), q)
    with pytest.raises(jflex.ShapeError):
        jflex.aba_derivatives(robot, q, q[:2], q)
    with pytest.raises(jflex.ParameterError):
        jflex.rnea_derivatives(robot.replace(inertia=np.zeros((3, 10))), q, q, q)
    with pytest.raises(jflex.ParameterError):
        jflex.aba_derivatives(robot.replace(inertia=np.zeros((3, 10))), q, q, q)


@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_gravity_stiffness_matches_pinocchio(name):
    robot, model = _urdf_pair(name)
    data = model.createData()
    rng = np.random.default_rng(5)
    for _ in range(2):
        q = _state(robot, rng)[0]
        close(jflex.gravity_stiffness(robot, q), pin.computeGeneralizedGravityDerivatives(model, data, q))


@pytest.mark.parametrize("seed", [0, 1])
def test_gravity_stiffness_matches_forward_mode_ad(seed):
    """The closed form on prismatic joints and tilted gravity (the Panda above is the branching tree)."""
    robot, rng = _dh_robot(seed)
    q = rng.normal(size=robot.nq)
    close(jflex.gravity_stiffness(robot, q), jax.jacfwd(lambda x: jflex.gravity(robot, x))(q))
