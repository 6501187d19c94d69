"""The identification regressor (``Regressor.stack``, computed in blocks by one compiled program)
against Pinocchio's ``computeJointTorqueRegressor`` on a branched robot with a prismatic joint,
and the same matrix when traced inside ``jax.jit``; bad input raises ``jflex.DataError``."""

import importlib.metadata as md

import jax
import numpy as np
import pytest

import jflex
from jflex import identify as idf

from _identify_helpers import arm_urdf

pin = pytest.importorskip("pinocchio")

# TIAGo's torso lift (prismatic) carries the head (2 joints) and the arm (7): a tree, not a chain
TIAGO_JOINTS = ["torso_lift_joint", "head_1_joint", "head_2_joint"] + [f"arm_{i}_joint" for i in range(1, 8)]


def _tiago_urdf():
    try:
        files = md.files("example-robot-data") or []
    except md.PackageNotFoundError:
        files = []
    for f in files:
        if str(f).replace("\\", "/").endswith("robots/tiago_description/robots/tiago_no_hand.urdf"):
            return str(f.locate())
    pytest.skip("example-robot-data with TIAGo is not installed")


@pytest.mark.filterwarnings("ignore:.*non-physical inertia")
def test_stack_matches_pinocchio_on_a_branched_robot_with_a_prismatic_joint():
    path = _tiago_urdf()
    robot = jflex.load_urdf(path, joints=TIAGO_JOINTS)
    full = pin.buildModelFromUrdf(path)
    model = pin.buildReducedModel(full, [full.getJointId(j) for j in full.names[1:] if j not in TIAGO_JOINTS], pin.neutral(full))
    data = model.createData()
    assert list(model.names[1:]) == list(robot.joint_names) and set(robot.joint_names) == set(TIAGO_JOINTS)
    assert len(set(robot.parents)) < robot.nq  # branched: a body with two children
    reg = idf.Regressor(viscous=True, coulomb=True)
    # more samples than one block, not a multiple of it: the padded last block is cut off
    q, qd, qdd = idf.random_samples(robot, 600, seed=4)
    A = np.asarray(reg.stack(robot, q, qd, qdd))
    n = robot.nq
    ref = np.concatenate([np.hstack([pin.computeJointTorqueRegressor(model, data, a, b, c), np.diag(b), np.diag(np.sign(b))])
                          for a, b, c in zip(q, qd, qdd)])
    assert A.shape == ref.shape == (600 * n, 12 * n)
    assert np.abs(A - ref).max() < 1e-10 * np.abs(ref).max()
    # the URDF's own inertias give Pinocchio's torques
    pi = np.concatenate([model.inertias[i].toDynamicParameters() for i in range(1, n + 1)])
    tau = np.stack([pin.rnea(model, data, a, b, c) for a, b, c in zip(q[:20], qd[:20], qdd[:20])])
    assert np.allclose(A[: 20 * n, : 10 * n] @ pi, tau.ravel(), rtol=1e-10, atol=1e-9)


def test_stack_traced_equals_stack_in_blocks():
    robot = jflex.from_urdf_string(arm_urdf(2))
    reg = idf.Regressor(viscous=True, coulomb=True, armature=True, compensator=(1, 2))
    q, qd, qdd = idf.random_samples(robot, 7, seed=5)
    A = np.asarray(reg.stack(robot, q, qd, qdd))
    A_jit = np.asarray(jax.jit(lambda r, a, b, c: reg.stack(r, a, b, c))(robot, q, qd, qdd))
    one = np.concatenate([np.asarray(reg(robot, a, b, c)) for a, b, c in zip(q, qd, qdd)])
    assert np.abs(A - A_jit).max() < 1e-12 * np.abs(A).max()
    assert np.abs(A - one).max() < 1e-12 * np.abs(A).max()


def test_stack_bad_input_raises_data_error():
    robot = jflex.from_urdf_string(arm_urdf(2))
    reg = idf.Regressor()
    q, qd, qdd = idf.random_samples(robot, 5, seed=1)
    with pytest.raises(jflex.DataError, match=r"Regressor\.stack.*'qd'.*expected shape \(5, 3\)"):
        reg.stack(robot, q, qd[:4], qdd)
    with pytest.raises(jflex.DataError, match=r"Regressor\.stack.*'q'.*expected shape \(N, 3\)"):
        reg.stack(robot, q[:, :2], qd[:, :2], qdd[:, :2])
    qdd = qdd.copy()
    qdd[3, 1] = np.nan
    with pytest.raises(jflex.DataError, match=r"Regressor\.stack.*'qdd'.*NaN/inf.*index \(3, 1\)"):
        reg.stack(robot, q, qd, qdd)
