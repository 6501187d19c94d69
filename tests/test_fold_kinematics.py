"""fold_kinematics: a model's placements, axes and gravity compiled in as constants.

Checked against the same function compiled with the whole model traced (equinox.filter_jit),
and by counting the operations of the two programs and the traces of the folded one."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import jflex
from jflex._fold import KINEMATICS, fold_kinematics
from jflex._model import model_forward_dynamics
from jflex.effects import FlexibleJoints

from _identify_helpers import staubli_like


def _arm():
    # right-angle placements and unit axes (a DH arm with a 90 degree twist), the case the folding is for
    spring = FlexibleJoints(jnp.asarray([800.0]), jnp.asarray([0.5]), jnp.asarray([0.05]), joints=(1,), coupling=False)
    return jflex.Model(staubli_like(), [spring])


def _fd(model, x, xd, u):
    return model_forward_dynamics(model, 0.0, x, xd, jnp.zeros(0), u)[0]


def _eqns(jaxpr) -> int:
    n = 0
    for e in jaxpr.eqns:
        n += 1
        for p in e.params.values():
            for q in p if isinstance(p, (tuple, list)) else [p]:
                inner = getattr(q, "jaxpr", q)
                if hasattr(inner, "eqns"):
                    n += _eqns(inner)
    return n


def test_folded_program_gives_the_traced_programs_numbers_with_fewer_operations():
    model = _arm()
    rng = np.random.default_rng(0)
    x, xd, u = (jnp.asarray(rng.normal(size=s)) for s in (4, 4, 3))
    folded = fold_kinematics(_fd)
    traced = eqx.filter_jit(_fd)
    np.testing.assert_allclose(folded(model, x, xd, u), traced(model, x, xd, u), rtol=1e-12, atol=1e-12)
    # the folded program's operations, counted on the function it compiles
    known = {f: np.asarray(getattr(model.robot, f)) for f in KINEMATICS}
    robot = eqx.tree_at(lambda r: [getattr(r, f) for f in known], model.robot, list(known.values()))
    n_folded = _eqns(jax.make_jaxpr(lambda inert, eff, *a: _fd(eqx.tree_at(lambda m: (m.robot.inertia, m.effects),
                                                                            eqx.tree_at(lambda m: m.robot, model, robot),
                                                                            (inert, eff)), *a))(
        model.robot.inertia, model.effects, x, xd, u).jaxpr)
    n_traced = _eqns(jax.make_jaxpr(_fd)(model, x, xd, u).jaxpr)
    assert n_folded < 0.75 * n_traced, (n_folded, n_traced)


def test_models_differing_in_physical_numbers_share_one_program():
    model = _arm()
    traces = []

    def fd(model, x, xd, u):
        traces.append(1)
        return _fd(model, x, xd, u)

    folded = fold_kinematics(fd)
    x, xd = jnp.asarray([0.3, -0.5, -0.45, 0.8]), jnp.zeros(4)  # the spring at joint 2 deflected
    u = jnp.asarray([0.0, 1.0, 0.0])
    a = folded(model, x, xd, u)
    heavier = eqx.tree_at(lambda m: m.robot.inertia, model, model.robot.inertia.at[2].multiply(1.5))
    stiffer = eqx.tree_at(lambda m: m.effects[0].stiffness, heavier, heavier.effects[0].stiffness * 2)
    b = folded(stiffer, x, xd, u)
    assert len(traces) == 1
    assert not np.allclose(a, b)  # the new numbers were used, not the first model's
    np.testing.assert_allclose(b, eqx.filter_jit(_fd)(stiffer, x, xd, u), rtol=1e-12, atol=1e-12)
    # other kinematics: a program of their own, with their numbers
    moved = eqx.tree_at(lambda m: m.robot.placement_p, model, model.robot.placement_p.at[2, 0].set(0.5))
    c = folded(moved, x, xd, u)
    assert len(traces) == 2
    np.testing.assert_allclose(c, eqx.filter_jit(_fd)(moved, x, xd, u), rtol=1e-12, atol=1e-12)


def test_inside_a_trace_the_function_runs_as_it_is():
    # a model traced by an enclosing jit has no known kinematics to fold: fn is called on it as given
    model = _arm()
    x, xd, u = jnp.asarray([0.3, -0.5, -0.45, 0.8]), jnp.zeros(4), jnp.asarray([0.0, 1.0, 0.0])
    outer = eqx.filter_jit(lambda m, *a: fold_kinematics(_fd)(m, *a))
    np.testing.assert_allclose(outer(model, x, xd, u), eqx.filter_jit(_fd)(model, x, xd, u), rtol=1e-12, atol=1e-12)
