"""The laws the gap diagnosis fits along a measured motion, as effects of a jflex.Model
(JointCompliance, Backlash, SensorDelay, DriveGain): one identity each, and the registry of effect
names that the diagnosis' tables are derived from."""

import numpy as np
import pytest

import jflex
from jflex import effects as E
from jflex._errors import ParameterError


def planar(n, gravity=(0.0, -9.81, 0.0)):
    rows = [[0.0, 0.0 if i == 0 else 0.5, 0.0, 0.0] for i in range(n)]
    inertias = [{"mass": 3.0 + i, "com": [0.25, 0.02, 0.0], "inertia": [0.1, 0.0, 0.2, 0.0, 0.0, 0.25]} for i in range(n)]
    return jflex.from_dh(rows, tool=[0.0, 0.5, 0.0, 0.0], inertias=inertias, gravity=gravity)


def _state(n, seed=0):
    rng = np.random.default_rng(seed)
    return rng.normal(size=n), rng.normal(size=n), rng.normal(size=n)


def _motion(n, N=400):
    t = np.linspace(0.0, 2.0, N)
    q = np.stack([0.3 * np.sin(2 * np.pi * (0.7 + 0.2 * j) * t) for j in range(n)], axis=1)
    return t, q


def test_neutral_effects_leave_the_inverse_dynamics_unchanged():
    robot = planar(2)
    q, qd, qdd = _state(2)
    ref = np.asarray(jflex.model_inverse_dynamics(jflex.Model(robot), 0.0, q, qd, qdd, np.zeros(0)))
    names = robot.joint_names
    for eff in (E.JointCompliance(names, 1e-3), E.Backlash(names, 0.01), E.SensorDelay(0.004), E.DriveGain(names, 1.0)):
        m = jflex.Model(robot, [eff])
        tau = np.asarray(jflex.model_inverse_dynamics(m, 0.0, q, qd, qdd, np.zeros(0)))
        np.testing.assert_array_equal(tau, ref)
    np.testing.assert_array_equal(np.asarray(jflex.input_matrix(jflex.Model(robot, [E.DriveGain(names, 1.0)]))),
                                  np.asarray(jflex.input_matrix(jflex.Model(robot))))


def test_drive_gain_scales_the_joint_torque():
    robot = planar(2)
    q, qd, _ = _state(2, 1)
    u = np.array([3.0, -2.0])
    g = 1.25
    plain = jflex.Model(robot)
    gained = jflex.Model(robot, [E.DriveGain([robot.joint_names[1]], g)])
    a, _ = jflex.model_forward_dynamics(gained, 0.0, q, qd, np.zeros(0), u)
    b, _ = jflex.model_forward_dynamics(plain, 0.0, q, qd, np.zeros(0), u * np.array([1.0, g]))
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
    # the command a motion needs is the torque over the gain
    tau = np.array([4.0, 5.0])
    cmd = gained.effects[0].command(robot, tau)
    np.testing.assert_allclose(cmd, [4.0, 5.0 / g], rtol=1e-15)
    c, _ = jflex.model_forward_dynamics(gained, 0.0, q, qd, np.zeros(0), cmd)
    d, _ = jflex.model_forward_dynamics(plain, 0.0, q, qd, np.zeros(0), tau)
    np.testing.assert_allclose(c, d, rtol=1e-12, atol=1e-12)
    with pytest.raises(ParameterError):
        E.DriveGain(robot.joint_names, 0.0)


def test_backlash_of_zero_is_the_identity_and_play_holds_at_reversals():
    robot = planar(2)
    t, q = _motion(2)
    np.testing.assert_array_equal(E.Backlash(robot.joint_names, 0.0).link_angles(robot, q), q)
    b = 0.02
    ql = jflex.Model(robot, [E.Backlash(robot.joint_names, b)]).effects[0].link_angles(robot, q)
    assert np.all(np.abs(ql - q) <= b + 1e-15)
    # the link holds still while the motor turns back across the play
    i = int(np.argmax(q[:, 0]))
    k = i + int(np.argmax(q[i:, 0] < q[i, 0] - 2 * b))
    assert k > i + 1 and np.all(ql[i:k, 0] == ql[i, 0])
    tau = np.tile(np.array([[1.0, -1.0]]), (len(t), 1))
    np.testing.assert_allclose(E.Backlash(robot.joint_names, b).loaded_link_angles(robot, q, tau + 0.1 * q)[:, 0],
                               q[:, 0] - b * E.loaded_play_side(tau[:, 0] + 0.1 * q[:, 0], 0.01))


def test_sensor_delay_shifts_a_signal_by_interpolation():
    t, q = _motion(2)
    d = 0.0123
    x = E.SensorDelay(d).apply(t, q)
    for j in range(2):
        np.testing.assert_array_equal(x[:, j], np.interp(t - d, t, q[:, j]))
    np.testing.assert_array_equal(E.SensorDelay(0.0).apply(t, q), q)


def test_compliance_deflection_is_torque_over_stiffness():
    robot = planar(2)
    t, q = _motion(2)
    tau = 30.0 * np.cos(q)
    k = np.array([2e4, 5e3])
    eff = jflex.Model(robot, [E.JointCompliance(robot.joint_names, 1.0 / k)]).effects[0]
    np.testing.assert_allclose(eff.deflection(robot, tau), tau / k, rtol=1e-15)
    np.testing.assert_allclose(eff.link_angles(robot, q, tau), q - tau / k, rtol=1e-15)
    with pytest.raises(ParameterError):
        E.JointCompliance(robot.joint_names, -1.0)


def test_the_gap_tables_follow_the_registry():
    from jflex.effects import _registry as REG
    from jflex.gap import EFFECT_NAMES
    from jflex.gap._effect_term import FAMILIES, FAMILY_META
    from jflex.gap._problem import CONFOUNDED
    from jflex.gap.frequency._kinds import SITE_KINDS
    from jflex.gap.judge._selection import NESTED
    from jflex.gap.torque._terms import KINDS

    assert REG.EFFECT_NAMES == EFFECT_NAMES
    assert tuple(KINDS) == tuple(n for n in REG.EFFECT_NAMES if REG.EFFECTS[n].torque)
    assert set(KINDS) - set(REG.TERMS) == set(E.registered_candidates())
    assert FAMILY_META is REG.FAMILY_META and FAMILIES == tuple(REG.FAMILY_META)
    assert {n: k.name for n, k in SITE_KINDS.items()} == {n: n for n in REG.SITE_EFFECTS}
    assert NESTED == {REG.STRIBECK_FRICTION: REG.COULOMB_FRICTION} and CONFOUNDED == REG.CONFOUNDED
