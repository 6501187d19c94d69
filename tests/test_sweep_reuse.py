"""sweep and batched as users call them: a second sweep reuses its compiled program (counted by
compilations, not timed), every batched program gives the same numbers, degenerate input is refused by
name or answered with an empty result, and a resume sees a robot however deeply it is held."""

import functools

import jax
import numpy as np
import pytest

import jflex
from test_sweep_resume import expected, pendulum

TRACES = {"n": 0}  # a module global, not a closure value: counting must not change the function


def gravity_of(robot):
    def fn(q):
        TRACES["n"] += 1  # runs only while JAX traces fn
        return jflex.gravity(robot, q)

    return fn


def traced_gravity(robot, q):
    TRACES["n"] += 1
    return jflex.gravity(robot, q)


@pytest.fixture
def q():
    return np.random.default_rng(2).uniform(-3, 3, (50, 1))


class Compiles:
    """Counts XLA backend compilations (JAX's monitoring events) while active."""

    def __enter__(self):
        from jax import monitoring

        self.n, self.on = 0, True
        monitoring.register_event_duration_secs_listener(self._seen)
        return self

    def _seen(self, name, secs, **kw):
        if self.on and name == "/jax/core/compile/backend_compile_duration":
            self.n += 1

    def __exit__(self, *exc):
        self.on = False


def test_second_sweep_reuses_the_compiled_program(q):
    with Compiles() as c:  # the first robot's numbers are compiled in as constants
        jflex.sweep(gravity_of(pendulum(2.0)), q, chunk_size=16, progress=False)
        first = c.n
    with Compiles() as c:  # a new closure over the same numbers: the same program
        jflex.sweep(gravity_of(pendulum(2.0)), q, chunk_size=16, progress=False)
    assert first >= 1 and c.n == 0
    with Compiles() as c:  # other numbers: one program taking them as arguments
        np.testing.assert_allclose(jflex.sweep(gravity_of(pendulum(9.0)), q, chunk_size=16, progress=False),
                                   expected(9.0, q), rtol=1e-12)
    assert c.n == first
    with Compiles() as c:
        for m in (3.0, 2.0, 7.0):  # a new closure each call, over a robot with other numbers
            out = jflex.sweep(gravity_of(pendulum(m)), q, chunk_size=16, progress=False)
            np.testing.assert_allclose(out, expected(m, q), rtol=1e-12)
    assert c.n == 0
    for m in (4.0, 6.0):
        jflex.sweep(functools.partial(traced_gravity, pendulum(m)), q, chunk_size=16, progress=False)
    with Compiles() as c:  # functools.partial over the robot
        out = jflex.sweep(functools.partial(traced_gravity, pendulum(5.0)), q, chunk_size=16, progress=False)
        np.testing.assert_allclose(out, expected(5.0, q), rtol=1e-12)
    assert c.n == 0
    with Compiles() as c:  # other shapes compile again
        jflex.sweep(gravity_of(pendulum(2.0)), q[:10], chunk_size=16, progress=False)
    assert c.n >= 1


def test_sweep_keeps_the_checks_of_a_plain_call(q):
    empty = pendulum(2.0).replace(inertia=np.zeros((1, 10)))
    with pytest.raises(jflex.ParameterError, match="no inertial parameters"):
        jflex.sweep(gravity_of(empty), q, progress=False)

    k = np.array(2.0)

    def branchy(x):  # Python control flow on a closed-over array: compiled with it as a constant
        return x * 2.0 if float(k) > 1 else x

    np.testing.assert_allclose(jflex.sweep(branchy, q, progress=False), 2.0 * q)


def test_sweep_over_an_empty_batch_returns_empty_outputs():
    out = jflex.sweep(lambda x: {"a": 2.0 * x, "s": x.sum()}, np.zeros((0, 3), np.float32), progress=False)
    assert out["a"].shape == (0, 3) and out["a"].dtype == np.float32
    assert out["s"].shape == (0,)


def test_sweep_out_dir_that_is_a_file_is_refused_by_name(q, tmp_path):
    f = tmp_path / "results.txt"
    f.write_text("not a folder")
    with pytest.raises(jflex.ConfigError, match="out_dir.*results.txt.*file"):
        jflex.sweep(gravity_of(pendulum(2.0)), q, out_dir=f, progress=False)
    assert f.read_text() == "not a folder"


def test_resume_sees_a_robot_held_deep_in_containers(q, tmp_path):
    def nested(m):
        held = {"a": {"b": {"c": {"d": {"e": [(pendulum(m),)]}}}}}
        return lambda x: jflex.gravity(held["a"]["b"]["c"]["d"]["e"][0][0], x)

    first = jflex.sweep(nested(2.0), q, chunk_size=16, out_dir=tmp_path, progress=False)
    np.testing.assert_allclose(first, expected(2.0, q), rtol=1e-12)
    with pytest.raises(jflex.DataError, match="different sweep"):
        jflex.sweep(nested(3.0), q, chunk_size=16, out_dir=tmp_path, progress=False)
    again = jflex.sweep(nested(2.0), q, chunk_size=16, out_dir=tmp_path, progress=False)
    np.testing.assert_array_equal(again, first)


def test_fingerprint_sees_arrays_at_any_depth():
    from jflex._fingerprint import fingerprint

    def deep(x, k):
        for _ in range(k):
            x = {"k": x}
        return x

    for k in (1, 4, 12):
        assert fingerprint(deep(np.zeros(3), k)) != fingerprint(deep(np.ones(3), k))
    import types

    assert fingerprint(types.SimpleNamespace(r=pendulum(2.0))) != fingerprint(types.SimpleNamespace(r=pendulum(3.0)))


def test_batched_programs_agree():
    robot = pendulum(2.0)
    rng = np.random.default_rng(0)
    q, v, a = rng.normal(size=(3, 300, 1))
    f = lambda q, v, a: jflex.rnea(robot, q, v, a)
    ref = np.asarray(jax.jit(jax.vmap(f))(q, v, a))
    for program in ("vmap", "blocks", "unfused", "barriers"):
        out = np.asarray(jflex.batched(f, program=program, batch_size=128)(q, v, a))
        np.testing.assert_allclose(out, ref, rtol=1e-12, atol=1e-12, err_msg=program)
    fastest = jflex.batched(f, program="fastest", batch_size=128)
    np.testing.assert_allclose(np.asarray(fastest(q, v, a)), ref, rtol=1e-12, atol=1e-12)
    assert list(fastest.choice.values())[0] in ("vmap", "blocks", "unfused", "barriers")
    fastest(q, v, a)
    assert len(fastest.choice) == 1  # the same shapes: no second measurement
    with pytest.raises(jflex.ConfigError, match="program"):
        jflex.batched(f, program="fast")
    from jflex._sweep import default_batch_size

    assert default_batch_size("cpu") == 1024 and default_batch_size("gpu") >= 1 << 16


def test_sweep_takes_the_users_choice_of_program(q):
    robot = pendulum(2.0)
    f = lambda x: jflex.gravity(robot, x)
    for program in ("vmap", "blocks", "fastest"):
        np.testing.assert_allclose(jflex.sweep(f, q, chunk_size=16, progress=False, program=program),
                                   expected(2.0, q), rtol=1e-12, err_msg=program)
    bad = q.copy()
    bad[40, 0] = np.nan  # the third chunk of 16: the message names the item in the whole sweep
    with pytest.raises(jflex.DataError, match=r"batch item 40"):
        jflex.sweep(f, bad, chunk_size=16, progress=False, program="blocks")
    with pytest.raises(jflex.ConfigError, match="sweep: program must be"):
        jflex.sweep(f, q, progress=False, program="fast")
