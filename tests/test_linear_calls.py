"""The public linear analyses as users call them: the same ``hold`` forms everywhere, results that
pass through ``jax.jit``, un-jitted calls that do not trace again, and a clear error for a robot
without inertia."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jflex
from jflex import _model
from jflex.effects import FlexibleJoints
from jflex.linear import _modal


def _robot(name="a"):
    # joint names key the compiled programs: a name of its own gives a test a fresh structure
    inert = [{"mass": 10.0, "com": [0.0, 0.0, -0.1], "inertia": [1.0, 0.0, 1.0, 0.0, 0.0, 1.0]}] * 3
    r = jflex.from_dh([[0, 0, 0.5, 0], [np.pi / 2, 0.2, 0, 0], [0, 0.8, 0, 0]], tool=[0, 0.5, 0, 0], inertias=inert)
    return dataclasses.replace(r, joint_names=tuple(f"{name}{i}" for i in range(3)))


def _model_of(robot, k=1e4):
    n = robot.nq
    return jflex.Model(robot, [FlexibleJoints(jnp.full(n, k), jnp.full(n, 5.0), jnp.full(n, 0.1), jnp.full(n, 50.0))])


Q = jnp.array([0.1, 0.4, -0.3])


def test_linearize_accepts_every_hold_form():
    model = _model_of(_robot())
    x0 = jflex.linear.expand_posture(model, Q)
    motors = model.layout.coord_names[3:]
    ref = jflex.linearize(model, x0, hold=motors)
    for hold in ("actuated", "theta_*", motors, (3, 4, 5), ["actuated"]):
        lin = jflex.linearize(model, x0, hold=hold)
        assert lin.names == ref.names == model.layout.coord_names[:3]
        np.testing.assert_array_equal(lin.K, ref.K)
    # the same forms as modal_analysis: the kept coordinates agree
    assert jflex.modal_analysis(model, Q, hold="actuated").names == ref.names
    with pytest.raises(jflex.ShapeError, match="matches no coordinate"):
        jflex.linearize(model, x0, hold="nope")


def test_linearization_unpacks_like_a_tuple():
    model = _model_of(_robot())
    lin = jflex.linearize(model, jflex.linear.expand_posture(model, Q), hold="actuated")
    M, C, K, B, names, keep = lin
    assert M is lin.M and names == lin.names and keep == (0, 1, 2) and len(lin) == 6
    assert lin[:3][2] is K


def test_jit_returns_linearisations_and_modes():
    model = _model_of(_robot())
    x0 = jflex.linear.expand_posture(model, Q)
    lin = jax.jit(lambda x: jflex.linearize(model, x, hold="actuated"))(x0)
    ref = jflex.linearize(model, x0, hold="actuated")
    assert lin.names == ref.names and lin.keep == ref.keep
    np.testing.assert_allclose(lin.K, ref.K, rtol=1e-12, atol=1e-9)
    modes = jax.jit(lambda q: jflex.modal_analysis(model, q, hold="actuated", solver="newton"))(Q)
    ref_modes = jflex.modal_analysis(model, Q, hold="actuated")  # eig
    assert modes.names == ref_modes.names
    np.testing.assert_allclose(modes.frequency, ref_modes.frequency, rtol=1e-10)
    # the robot and model as arguments of jit
    lin2 = jax.jit(lambda m, x: jflex.linearize(m, x, hold="actuated"))(model, x0)
    np.testing.assert_allclose(lin2.M, ref.M, rtol=1e-12, atol=1e-12)


def test_unjitted_calls_do_not_trace_again(monkeypatch):
    traces = {"linearize": 0, "modal": 0}
    mass, modes = _model.mass_matrix, _modal.modes

    def count_mass(*a, **k):
        traces["linearize"] += 1
        return mass(*a, **k)

    def count_modes(*a, **k):
        traces["modal"] += 1
        return modes(*a, **k)

    monkeypatch.setattr(_model, "mass_matrix", count_mass)
    monkeypatch.setattr(_modal, "modes", count_modes)
    robot = _robot("trace_once_")
    model = _model_of(robot)
    x0 = jflex.linear.expand_posture(model, Q)
    m1 = jflex.modal_analysis(model, Q, hold="actuated")
    l1 = jflex.linearize(model, x0, hold="actuated")
    assert traces["modal"] == 1 and traces["linearize"] >= 1
    seen = dict(traces)
    # another posture, and another model of the same robot and structure: no new trace
    other = _model_of(robot, k=3e4)
    m2 = jflex.modal_analysis(other, Q + 0.2, hold="actuated")
    l2 = jflex.linearize(other, x0 + 0.2, hold="actuated")
    assert traces == seen
    # ... and the compiled program's answers are those of the new numbers
    assert not np.allclose(m1.frequency, m2.frequency) and not np.allclose(l1.K, l2.K)
    ref = jax.jit(lambda m, q: jflex.modal_analysis(m, q, hold="actuated").frequency)(other, Q + 0.2)
    np.testing.assert_allclose(m2.frequency, ref, rtol=1e-12)
    # another hold is another program: the counter does see traces
    before = traces["modal"]
    jflex.modal_analysis(model, Q, hold=())
    assert traces["modal"] == before + 1


def test_modal_analysis_of_a_robot_without_inertia_raises():
    robot = _robot()
    bare = robot.replace(inertia=jnp.zeros_like(robot.inertia))
    with pytest.raises(jflex.ParameterError, match="inertia"):
        jflex.modal_analysis(_model_of(bare), Q, hold="actuated")
    # a free motor coordinate without rotor inertia: a singular mass matrix, named
    n = robot.nq
    no_rotor = jflex.Model(robot, [FlexibleJoints(jnp.full(n, 1e4), jnp.full(n, 5.0), None, jnp.full(n, 50.0))])
    with pytest.raises(jflex.ParameterError, match="not positive definite"):
        jflex.modal_analysis(no_rotor, Q)
    with pytest.raises(Exception, match="not positive definite"):
        jax.jit(lambda m: jflex.modal_analysis(m, Q).frequency)(no_rotor).block_until_ready()


def test_a_nearly_zero_joint_stiffness_finishes_and_says_what_it_found():
    # a spring of 1e-9 N m/rad at the vertical first joint leaves that link free about its axis
    # (with its damper: an overdamped, near-zero pole); neither solver hangs (a case with such a
    # nominal stiffness once ran past 300 s): eig returns finite modes, newton returns them or
    # names the solver that can
    n = 3
    soft = jflex.Model(_robot("soft"), [FlexibleJoints(jnp.array([1e-9, 1e4, 1e4]), jnp.full(n, 5.0), jnp.full(n, 0.1),
                                                       jnp.full(n, 50.0))])
    md = jflex.modal_analysis(soft, Q, hold="actuated", solver="eig")
    f = np.asarray(md.frequency)
    assert np.all(np.isfinite(f)) and np.all(np.isfinite(np.asarray(md.damping_ratio)))
    stiff = jflex.modal_analysis(_model_of(_robot("soft")), Q, hold="actuated", solver="eig")
    assert f.min() < 1e-2 * float(np.asarray(stiff.frequency).min())  # the soft joint's mode, near 0 Hz
    try:
        mn = jflex.modal_analysis(soft, Q, hold="actuated", solver="newton")
        assert np.all(np.isfinite(np.asarray(mn.frequency)))
    except Exception as exc:  # raised inside the compiled program (eqx.error_if): names the solver to use
        assert "solver='eig'" in str(exc)
