"""Checked inputs at the dynamics boundary (issue 15 item 4): NaN/inf states raise, named, eagerly
and inside jit/vmap; a joint that moves no inertia and a robot without inertial parameters raise a
ParameterError instead of dividing by zero or returning zeros; kinematics need no inertia."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jflex

# a 3-joint arm with masses: the Staubli TX200 kinematics of configs/robots with demo-like links
LINKS = np.array([
    [250.0, 0.0, 0.0, -37.5, 17.6, 0.0, 17.6, 0.0, 0.0, 9.0],
    [160.0, 72.0, 0.0, 32.0, 9.4, 0.0, 52.8, -14.4, 0.0, 46.4],
    [90.0, 36.0, 0.0, 0.0, 1.5, 0.0, 22.4, 0.0, 0.0, 22.4],
])


@pytest.fixture(scope="module")
def arm():
    return jflex.load_robot("staubli_tx200").replace(inertia=LINKS)


def pendulum(m=2.0, l=0.5, g=9.81):
    """One revolute joint about y carrying a point mass m at x = l (gravity along -z)."""
    return jflex.make_robot(
        joint_names=["j"], link_names=["bob"], parents=[-1], joint_types=["revolute"],
        placement_R=np.eye(3)[None], placement_p=np.zeros((1, 3)), axis=[[0, 1.0, 0]],
        inertia=[[m, m * l, 0, 0, 0, 0, m * l * l, 0, 0, m * l * l]], gravity=(0, 0, -g),
    )


CALLS = {  # public function -> (call, its argument names)
    "rnea": (lambda r, a: jflex.rnea(r, a["q"], a["qd"], a["qdd"]), ("q", "qd", "qdd")),
    "crba": (lambda r, a: jflex.crba(r, a["q"]), ("q",)),
    "aba": (lambda r, a: jflex.aba(r, a["q"], a["qd"], a["tau"]), ("q", "qd", "tau")),
    "forward_dynamics": (lambda r, a: jflex.forward_dynamics(r, a["q"], a["qd"], a["tau"]), ("q", "qd", "tau")),
    "forward_dynamics (method='crba')": (
        lambda r, a: jflex.forward_dynamics(r, a["q"], a["qd"], a["tau"], method="crba"), ("q", "qd", "tau")),
    "jacobian": (lambda r, a: jflex.jacobian(r, a["q"], "tool"), ("q",)),
    "forward_kinematics": (lambda r, a: jflex.forward_kinematics(r, a["q"]), ("q",)),
    "gravity": (lambda r, a: jflex.gravity(r, a["q"]), ("q",)),
}
CASES = [(fn, arg, bad) for fn, (_, args) in CALLS.items() for arg in args for bad in (np.nan, np.inf)]


def _args(bad_arg=None, value=np.nan, n=3):
    a = {k: np.array([0.3, -0.4, 0.5])[:n] for k in ("q", "qd", "qdd", "tau")}
    if bad_arg:
        a[bad_arg] = a[bad_arg].copy()
        a[bad_arg][1] = value
    return a


@pytest.mark.parametrize("fn,arg,bad", CASES)
def test_non_finite_argument_raises_named(arm, fn, arg, bad):
    call, _ = CALLS[fn]
    with pytest.raises(jflex.DataError) as e:
        call(arm, _args(arg, bad))
    assert str(e.value).startswith(f"{fn}: {arg} contains NaN/inf")
    assert "entries [1]" in str(e.value)


@pytest.mark.parametrize("fn", ["rnea", "forward_dynamics", "forward_dynamics (method='crba')", "jacobian"])
def test_non_finite_argument_raises_inside_jit(arm, fn):
    """Robot and state traced (jit with everything as arguments): the run-time error names the
    function and the argument; vmap over a batch with one bad row raises too."""
    call, args = CALLS[fn]
    f = jax.jit(lambda r, a: call(r, a))
    good = {k: jnp.asarray(v) for k, v in _args().items()}
    out = f(arm, good)
    assert bool(jnp.all(jnp.isfinite(out)))
    bad_arg = args[-1]
    with pytest.raises(Exception, match=rf"{fn}: {bad_arg} contains NaN/inf".replace("(", r"\(").replace(")", r"\)")):
        jax.block_until_ready(f(arm, {k: jnp.asarray(v) for k, v in _args(bad_arg, np.inf).items()}))
    if fn == "rnea":
        batch = {k: jnp.tile(v, (5, 1)) for k, v in good.items()}
        vf = jax.jit(jax.vmap(lambda a: call(arm, a)))
        assert vf(batch).shape == (5, 3)
        batch["qd"] = batch["qd"].at[3, 2].set(jnp.nan)
        with pytest.raises(Exception, match="rnea: qd contains NaN/inf"):
            jax.block_until_ready(vf(batch))


def test_checks_keep_results_closed_form():
    """Pendulum: tau = m l^2 qdd - m g l cos(q) about +y (q = 0: bob level with the pivot; a
    positive q turns +x towards -z, so gravity pushes q up and the joint must pull back)."""
    m, l, g = 2.0, 0.5, 9.81
    r = pendulum(m, l, g)
    for q, qdd in [(0.0, 0.0), (0.7, 1.3), (-2.0, -0.4)]:
        tau = m * l * l * qdd - m * g * l * np.cos(q)
        assert float(jflex.rnea(r, [q], [0.3], [qdd])[0]) == pytest.approx(tau, rel=1e-12)
        assert float(jax.jit(jflex.rnea)(r, jnp.array([q]), jnp.array([0.3]), jnp.array([qdd]))[0]) == pytest.approx(tau, rel=1e-12)
        assert float(jflex.forward_dynamics(r, [q], [0.3], [tau])[0]) == pytest.approx(qdd, abs=1e-12)


def test_string_posture_is_a_data_error(arm):
    with pytest.raises(jflex.DataError, match="rnea: q must be numbers"):
        jflex.rnea(arm, ["a", "b", "c"], np.zeros(3), np.zeros(3))


def test_f_ext_shape_and_finite(arm):
    with pytest.raises(jflex.DataError, match=r"rnea: f_ext must have shape \(3, 6\)"):
        jflex.rnea(arm, np.zeros(3), np.zeros(3), np.zeros(3), f_ext=np.zeros((3, 3)))
    f = np.zeros((3, 6))
    f[2, 4] = np.nan
    with pytest.raises(jflex.DataError, match="rnea: f_ext contains NaN/inf"):
        jflex.rnea(arm, np.zeros(3), np.zeros(3), np.zeros(3), f_ext=f)


@pytest.mark.parametrize("method", ["aba", "crba"])
def test_zero_inertia_end_link_is_named(arm, method):
    r = arm.replace(inertia=arm.inertia.at[2].set(0.0))
    z = np.zeros(3)
    with pytest.raises(jflex.ParameterError, match="joint 'joint3' moves no inertia: link 'link3'"):
        jflex.forward_dynamics(r, z, z, z, method=method)
    if method == "aba":
        with pytest.raises(jflex.ParameterError, match="^aba: joint 'joint3'"):
            jflex.aba(r, z, z, z)
    # with the robot traced the same singularity is a run-time error, not a NaN or a ZeroDivisionError
    f = jax.jit(lambda rr: jflex.forward_dynamics(rr, jnp.zeros(3), jnp.zeros(3), jnp.ones(3), method=method))
    assert bool(jnp.all(jnp.isfinite(f(arm))))
    with pytest.raises(Exception, match="mass matrix is singular|not positive definite"):
        jax.block_until_ready(f(r))
    # the mass matrix itself is still returned (zero last row and column, by its definition)
    M = np.asarray(jflex.crba(r, z))
    assert np.all(M[2] == 0) and np.all(M[:, 2] == 0) and M[0, 0] > 0


def test_prismatic_joint_needs_mass():
    """A prismatic end link with rotational inertia but no mass moves nothing along its axis."""
    r = jflex.make_robot(
        joint_names=["rot", "slide"], link_names=["hub", "rod"], parents=[-1, 0], joint_types=["revolute", "prismatic"],
        placement_R=np.stack([np.eye(3)] * 2), placement_p=np.zeros((2, 3)), axis=[[0, 0, 1.0], [1.0, 0, 0]],
        inertia=[[1.0, 0, 0, 0, 0.1, 0, 0.1, 0, 0, 0.1], [0.0, 0, 0, 0, 0.1, 0, 0.1, 0, 0, 0.1]], gravity=(0, 0, 0),
    )
    with pytest.raises(jflex.ParameterError, match="joint 'slide' moves no inertia: link 'rod'.*zero mass,"):
        jflex.forward_dynamics(r, np.zeros(2), np.zeros(2), np.zeros(2))


@pytest.mark.parametrize("name", ["staubli_tx200", "kuka_kr90"])
def test_shipped_kinematic_configs_refuse_dynamics(name):
    """configs/robots/{staubli_tx200,kuka_kr90}.yaml carry kinematics only (seed 003 gives base
    parameters, not link masses; its code realises link inertias from them): dynamics say so,
    kinematics and the regressor work."""
    r = jflex.load_robot(name)
    z = np.zeros(3)
    for fn, call in [("rnea", lambda: jflex.rnea(r, z, z, z)), ("crba", lambda: jflex.crba(r, z)),
                     ("gravity", lambda: jflex.gravity(r, z)), ("forward_dynamics", lambda: jflex.forward_dynamics(r, z, z, z))]:
        with pytest.raises(jflex.ParameterError, match=rf"^{fn}: the robot .* has no inertial parameters.*robot.inertia"):
            call()
    T = np.asarray(jflex.forward_kinematics(r, z))
    J = np.asarray(jflex.jacobian(r, z, "tool"))
    Y = np.asarray(jflex.regressor(r, z, z, np.ones(3)))
    assert T.shape == (3, 4, 4) and J.shape == (6, 3) and Y.shape == (3, 30)
    # the base sits on the first joint axis: joint 1 moves the tool in the horizontal plane only
    assert abs(J[2, 0]) < 1e-12 and np.linalg.norm(J[:2, 0]) > 0.5
