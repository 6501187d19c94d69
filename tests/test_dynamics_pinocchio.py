"""Rigid-body algorithms against Pinocchio (float64, 1e-9 relative) on the UR5 and Panda URDFs of
example-robot-data and on random robots (hypothesis)."""

import os

import numpy as np
import pytest
import jax.numpy as jnp
from hypothesis import given, settings, strategies as st

import jflex
from jflex._tree import body_placement
from _references import dh_chain, pin, pin_model_from_robot, random_inertia_params

pytestmark = pytest.mark.skipif(pin is None, reason="needs the test extra 'pin'")

RTOL = 1e-9


def close(a, b, rtol=RTOL):
    a, b = np.asarray(a), np.asarray(b)
    b = b.reshape(a.shape)  # Pinocchio drops singleton axes for 1-joint robots
    scale = max(1.0, np.abs(b).max())
    np.testing.assert_allclose(a, b, rtol=0, atol=rtol * scale)


def _sym(M):
    return np.triu(M) + np.triu(M, 1).T


def compare_all(robot, model, rng, frame=None):
    data = model.createData()
    n = robot.nq
    lo = np.where(np.isfinite(robot.lower), robot.lower, -np.pi)
    hi = np.where(np.isfinite(robot.upper), robot.upper, np.pi)
    q = rng.uniform(lo, hi)
    qd, qdd = rng.normal(size=n), rng.normal(size=n)
    fext = rng.normal(size=(n, 6))
    tau = pin.rnea(model, data, q, qd, qdd)
    close(jflex.rnea(robot, q, qd, qdd), tau)
    pin_f = [pin.Force.Zero()] + [pin.Force(f[:3], f[3:]) for f in fext]
    close(jflex.rnea(robot, q, qd, qdd, f_ext=fext), pin.rnea(model, data, q, qd, qdd, pin_f))
    close(jflex.crba(robot, q), _sym(pin.crba(model, data, q)))
    close(jflex.nonlinear_effects(robot, q, qd), pin.nonLinearEffects(model, data, q, qd))
    close(jflex.gravity(robot, q), pin.computeGeneralizedGravity(model, data, q))
    close(jflex.aba(robot, q, qd, tau), pin.aba(model, data, q, qd, tau))
    close(jflex.forward_dynamics(robot, q, qd, tau, method="crba"), qdd)
    close(jflex.aba(robot, q, qd, tau, f_ext=fext), pin.aba(model, data, q, qd, tau, pin_f))
    close(jflex.regressor(robot, q, qd, qdd), pin.computeJointTorqueRegressor(model, data, q, qd, qdd))
    close(jflex.kinetic_energy(robot, q, qd), pin.computeKineticEnergy(model, data, q, qd))
    close(jflex.potential_energy(robot, q), pin.computePotentialEnergy(model, data, q))
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    T = jflex.forward_kinematics(robot, q)
    for i in range(n):
        close(T[i], data.oMi[i + 1].homogeneous)
        # the array-algebra chain the flexible link differentiates (jflex._tree.body_placement)
        R, p = body_placement(robot, jnp.asarray(q), i)
        close(R, data.oMi[i + 1].rotation)
        close(p, data.oMi[i + 1].translation)
    pin.computeJointJacobians(model, data, q)
    for i in range(n):
        for ref, pref in [("local", pin.LOCAL), ("world", pin.WORLD), ("local_world_aligned", pin.LOCAL_WORLD_ALIGNED)]:
            close(jflex.jacobian(robot, q, i, reference=ref), pin.getJointJacobian(model, data, i + 1, pref))
    if frame is not None:
        fid = model.getFrameId(frame)
        close(jflex.frame_placement(robot, q, frame), data.oMf[fid].homogeneous)
        J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
        close(jflex.jacobian(robot, q, frame), J)


@pytest.mark.parametrize("name,frame", [("ur5", "tool0"), ("panda", "panda_hand")])
def test_urdf_robots_match_pinocchio(name, frame):
    if name not in jflex.available_robots():
        pytest.skip("example-robot-data not installed")
    from jflex._config import _example_robot_urdf

    path = str(_example_robot_urdf(name))
    robot = jflex.load_urdf(path, mimic="independent")  # the Panda's fingers, as Pinocchio loads them
    model = pin.buildModelFromUrdf(path)
    assert robot.joint_names == tuple(model.names[1:])
    rng = np.random.default_rng(1)
    for _ in range(3):
        compare_all(robot, model, rng, frame=frame)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(1, 7), standard=st.booleans())
def test_random_dh_robots_match_pinocchio(seed, n, standard):
    rng = np.random.default_rng(seed)
    table = np.column_stack(
        [rng.uniform(-np.pi, np.pi, n), rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(-np.pi, np.pi, n)]
    )
    types = list(rng.choice(["revolute", "prismatic"], n))
    convention = "standard" if standard else "modified"
    inert = [random_inertia_params(rng) for _ in range(n)]
    robot = jflex.from_dh(table, convention=convention, joint_types=types, inertias=inert, tool=[0.1, 0.2, 0.3, 0.4])
    compare_all(robot, pin_model_from_robot(robot), rng)
    # the DH builder itself, against the textbook DH product
    q = rng.uniform(-1, 1, n)
    frames = dh_chain(table, q, types, convention)
    if convention == "modified":
        close(jflex.forward_kinematics(robot, q), np.stack(frames))
    else:
        for i in range(n):
            close(jflex.frame_placement(robot, q, f"dh{i + 1}"), frames[i])


@pytest.mark.slow
@pytest.mark.parametrize("program", ["vmap", "barriers", "blocks", "unfused"])
def test_batched_kernels_match_pinocchio(program):
    # the batch paths the benchmarks time: the default one vmapped program, the same with the
    # kernels' optimization barriers kept through XLA:CPU's fusion, blocks, and one unfused program
    # (where XLA:CPU once miscompiled lax.map blocks and RNEA/ABA came out wrong by O(1)); the
    # benchmarks' Panda at full size (JFLEX_SLOW=1), else a random 3-joint DH arm with a prismatic
    # joint (the Panda's six batched programs compile for minutes on 2 cores, a UR5's for over one;
    # the unfused programs' compile grows with the unrolled traversal, one joint less is a quarter less)
    if os.environ.get("JFLEX_SLOW") == "1":
        if "panda" not in jflex.available_robots():
            pytest.skip("example-robot-data not installed")
        from jflex._config import _example_robot_urdf

        path = str(_example_robot_urdf("panda"))
        robot = jflex.load_urdf(path, mimic="independent")  # the Panda's fingers, as Pinocchio loads them
        model = pin.buildModelFromUrdf(path)
    else:
        g = np.random.default_rng(7)
        table = np.column_stack([g.uniform(-np.pi, np.pi, 3), g.uniform(-1, 1, 3), g.uniform(-1, 1, 3), g.uniform(-np.pi, np.pi, 3)])
        robot = jflex.from_dh(table, joint_types=["revolute", "prismatic", "revolute"],
                              inertias=[random_inertia_params(g) for _ in range(3)], gravity=[0.0, 0.0, -9.81])
        model = pin_model_from_robot(robot)
    data = model.createData()
    rng = np.random.default_rng(3)
    N = 300  # > batch_size: several blocks and a ragged last one
    q = rng.uniform(-1.5, 1.5, (N, robot.nq))
    qd, qdd = rng.normal(size=(2, N, robot.nq))
    kernels = {
        "rnea": (lambda a, b, c: jflex.rnea(robot, a, b, c), lambda i: pin.rnea(model, data, q[i], qd[i], qdd[i])),
        "crba": (lambda a, b, c: jflex.crba(robot, a), lambda i: pin.crba(model, data, q[i])),
        "aba": (lambda a, b, c: jflex.aba(robot, a, b, c), lambda i: pin.aba(model, data, q[i], qd[i], qdd[i])),
    }
    for name, (f, ref) in kernels.items():
        out = np.asarray(jflex.batched(f, program=program, batch_size=128 if program == "blocks" else None)(q, qd, qdd))
        R = np.array([np.array(ref(i), copy=True) for i in range(N)])
        if name == "crba":
            R = np.triu(R) + np.swapaxes(np.triu(R, 1), 1, 2)
        np.testing.assert_allclose(out, R, rtol=1e-9, atol=1e-9 * np.abs(R).max(), err_msg=f"{name}, {program}")


def _fd(f, x, h=1e-6):
    """Central differences of f at x, column per coordinate."""
    cols = []
    for k in range(len(x)):
        e = np.zeros(len(x))
        e[k] = h
        cols.append((np.asarray(f(x + e)) - np.asarray(f(x - e))) / (2 * h))
    return np.stack(cols, axis=-1)


def test_coupled_panda_matches_pinocchio():
    # the Panda as it ships: finger 2 mimics finger 1, one coordinate for both (Pinocchio's
    # mimic=True); where Pinocchio has no mimic support (regressor, energies, derivatives, ABA) the
    # reference is its independent model at q_full = G q (multiplier 1, offset 0), or differences
    if "panda" not in jflex.available_robots():
        pytest.skip("example-robot-data not installed")
    from jflex._config import _example_robot_urdf

    path = str(_example_robot_urdf("panda"))
    robot = jflex.load_urdf(path)
    model, full = pin.buildModelFromUrdf(path, mimic=True), pin.buildModelFromUrdf(path)
    data, fdata = model.createData(), full.createData()
    n = robot.nq
    assert n == model.nv == 8 and robot.n_joints == full.nv == 9
    G = np.vstack([np.eye(8), np.eye(8)[7]])
    rng = np.random.default_rng(5)
    q = rng.uniform(np.asarray(robot.lower)[:8], np.asarray(robot.upper)[:8])
    qd, qdd = rng.normal(size=n), rng.normal(size=n)
    fext = rng.normal(size=(9, 6))  # one wrench per body of the tree
    tau = pin.rnea(model, data, q, qd, qdd)
    close(jflex.rnea(robot, q, qd, qdd), tau)
    pin_f = [pin.Force.Zero()] + [pin.Force(f[:3], f[3:]) for f in fext]
    close(jflex.rnea(robot, q, qd, qdd, f_ext=fext), G.T @ pin.rnea(full, fdata, G @ q, G @ qd, G @ qdd, pin_f))
    with pytest.raises(jflex.DataError, match=r"f_ext must have shape \(9, 6\)"):
        jflex.rnea(robot, q, qd, qdd, f_ext=fext[:8])
    with pytest.raises(jflex.ShapeError, match=r"q must have shape \(8,\)"):
        jflex.rnea(robot, G @ q, G @ qd, G @ qdd)
    M = _sym(pin.crba(model, data, q))
    close(jflex.crba(robot, q), M)
    close(jflex.nonlinear_effects(robot, q, qd), pin.nonLinearEffects(model, data, q, qd))
    close(jflex.gravity(robot, q), pin.computeGeneralizedGravity(model, data, q))
    for method in ("aba", "crba"):
        close(jflex.forward_dynamics(robot, q, qd, tau, method=method), qdd)
    close(jflex.aba(robot, q, qd, tau), qdd)
    tau_f = np.asarray(jflex.rnea(robot, q, qd, qdd, f_ext=fext))
    close(jflex.aba(robot, q, qd, tau_f, f_ext=fext), qdd)
    Y = np.asarray(jflex.regressor(robot, q, qd, qdd))
    close(Y, G.T @ pin.computeJointTorqueRegressor(full, fdata, G @ q, G @ qd, G @ qdd))
    close(Y @ np.asarray(robot.inertia).ravel(), tau)
    close(jflex.kinetic_energy(robot, q, qd), pin.computeKineticEnergy(full, fdata, G @ q, G @ qd))
    close(jflex.potential_energy(robot, q), pin.computePotentialEnergy(full, fdata, G @ q))
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    T = jflex.forward_kinematics(robot, q)
    for i in range(9):
        close(T[i], data.oMi[i + 1].homogeneous)
    pin.computeJointJacobians(model, data, q)
    for i in (6, 7, 8):
        for ref, pref in [("local", pin.LOCAL), ("world", pin.WORLD), ("local_world_aligned", pin.LOCAL_WORLD_ALIGNED)]:
            close(jflex.jacobian(robot, q, i, reference=ref), pin.getJointJacobian(model, data, i + 1, pref))
    fid = model.getFrameId("panda_rightfinger")
    close(jflex.frame_placement(robot, q, "panda_rightfinger"), data.oMf[fid].homogeneous)
    close(jflex.jacobian(robot, q, "panda_rightfinger"), pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED))
    # derivatives against central differences of Pinocchio's coupled rnea and of M^-1 (tau - h)
    dq, dv, dM = jflex.rnea_derivatives(robot, q, qd, qdd)
    close(dq, _fd(lambda x: pin.rnea(model, data, x, qd, qdd), q), rtol=1e-6)
    close(dv, _fd(lambda x: pin.rnea(model, data, q, x, qdd), qd), rtol=1e-6)
    close(dM, M)

    def fwd(x, v, t):
        return np.linalg.solve(_sym(pin.crba(model, data, x)), t - pin.nonLinearEffects(model, data, x, v))

    aq, av, at = jflex.aba_derivatives(robot, q, qd, tau)
    close(aq, _fd(lambda x: fwd(x, qd, tau), q), rtol=1e-6)
    close(av, _fd(lambda x: fwd(q, x, tau), qd), rtol=1e-6)
    close(at, np.linalg.inv(M), rtol=1e-8)


def test_forward_dynamics_method_is_named():
    robot = jflex.from_dh([[0.0, 0.0, 1.0, 0.0]], inertias=[[1.0, 0.5, 0, 0, 0.1, 0, 0.4, 0, 0, 0.4]])
    z = np.zeros(1)
    with pytest.raises(jflex.JFlexError, match=r"forward_dynamics: method must be 'aba' or 'crba', got 'foo'"):
        jflex.forward_dynamics(robot, z, z, z, method="foo")
    with pytest.raises(jflex.JFlexError, match=r"jacobian: reference must be one of"):
        jflex.jacobian(robot, z, 0, reference="base")
