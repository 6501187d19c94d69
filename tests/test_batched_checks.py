"""jflex.batched keeps the library's run-time checks without a callback into Python inside the
compiled batch program (a GPU would hand control back to the host on every call): the checks
come back as flags and the host raises the failed one's message, naming the batch item."""

import pathlib
import re

import jax
import numpy as np
import pinocchio as pin
import pytest

import jflex

ARM = """<robot name="arm">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0.1 0 0.2"/><mass value="2.0"/>
    <inertia ixx="0.02" ixy="0.001" ixz="0" iyy="0.03" iyz="0" izz="0.015"/></inertial></link>
  <link name="l2"><inertial><origin xyz="0.25 0 0"/><mass value="1.5"/>
    <inertia ixx="0.01" ixy="0" ixz="0.002" iyy="0.04" iyz="0" izz="0.04"/></inertial></link>
  <link name="l3"><inertial><origin xyz="0.1 0.02 0"/><mass value="0.7"/>
    <inertia ixx="0.003" ixy="0" ixz="0" iyy="0.005" iyz="0.0005" izz="0.004"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="100" velocity="5"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.3" rpy="0.3 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="100" velocity="5"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0.5 0 0"/>
    <axis xyz="1 0 0"/><limit lower="-3" upper="3" effort="100" velocity="5"/></joint>
</robot>"""


@pytest.fixture(scope="module")
def arm():
    return jflex.from_urdf_string(ARM, name="arm"), pin.buildModelFromXML(ARM)


def _callbacks(program, *args):
    text = program.lower(*args).compile().as_text()
    return {t for t in re.findall(r'custom_call_target="([^"]+)"', text) if "callback" in t or "python" in t}


KERNELS = {
    "rnea": (lambda r, q, v, x: jflex.rnea(r, q, v, x), lambda m, d, q, v, x: pin.rnea(m, d, q, v, x)),
    "aba": (lambda r, q, v, x: jflex.aba(r, q, v, x), lambda m, d, q, v, x: pin.aba(m, d, q, v, x)),
}


@pytest.mark.parametrize("program", ["vmap", "blocks"])
@pytest.mark.parametrize("kernel", list(KERNELS))
def test_no_host_callback_and_same_numbers(arm, kernel, program):
    robot, model = arm
    data = model.createData()
    rng = np.random.default_rng(4)
    q, v, x = rng.uniform(-2, 2, (3, 10, robot.nq))
    f = lambda q, v, x: KERNELS[kernel][0](robot, q, v, x)
    b = jflex.batched(f, program=program, batch_size=4)
    out = np.asarray(b(q, v, x))
    ref = np.array([KERNELS[kernel][1](model, data, q[i], v[i], x[i]) for i in range(10)])
    np.testing.assert_allclose(out, ref, rtol=1e-10, atol=1e-10)
    # the program a user's call ran holds no callback; a plain jit(vmap) of the same kernel does
    # (its eqx.error_if), which is what makes this check able to fail
    assert _callbacks(b._flagged, q, v, x) == set()
    assert _callbacks(jax.jit(jax.vmap(f)), q, v, x)


def test_nan_input_raises_naming_the_item(arm):
    robot, _ = arm
    q = np.zeros((8, robot.nq))
    q[5, 1] = np.nan
    b = jflex.batched(lambda q: jflex.gravity(robot, q))
    with pytest.raises(jflex.DataError, match=r"contains NaN/inf \(batch item 5"):
        b(q)
    assert np.isfinite(np.asarray(b(np.zeros((8, robot.nq))))).all()


def test_inside_a_callers_jit_the_checks_stay(arm):
    robot, _ = arm
    b = jflex.batched(lambda q: jflex.gravity(robot, q))
    q = np.random.default_rng(1).uniform(-1, 1, (6, robot.nq))
    total = jax.jit(lambda q: b(q).sum())
    np.testing.assert_allclose(float(total(q)), float(np.asarray(b(q)).sum()), rtol=1e-12)
    bad = q.copy()
    bad[2, 0] = np.inf
    with pytest.raises(Exception, match="NaN/inf"):
        jax.block_until_ready(total(bad))


def test_a_check_inside_the_functions_own_loop_keeps_error_if(arm):
    # a guard traced inside fn's lax loop cannot leave the loop as a flag: the program with the
    # checks inside is used instead, with the same numbers
    robot, _ = arm
    g = lambda q: jax.lax.fori_loop(0, 2, lambda i, x: x + jflex.gravity(robot, q), q * 0)
    b = jflex.batched(g)
    q = np.random.default_rng(0).uniform(-1, 1, (6, robot.nq))
    np.testing.assert_allclose(np.asarray(b(q)), np.asarray(jax.vmap(g)(q)), rtol=1e-12, atol=1e-12)
    bad = q.copy()
    bad[3, 1] = np.nan
    with pytest.raises(Exception, match="NaN/inf"):
        jax.block_until_ready(b(bad))


def test_sweep_raises_a_failed_check_naming_the_item_of_the_whole_sweep(arm):
    robot, _ = arm
    q = np.random.default_rng(0).uniform(-1, 1, (50, robot.nq))
    f = lambda q: jflex.aba(robot, q, q, q)
    np.testing.assert_allclose(jflex.sweep(f, q, chunk_size=16, progress=False), np.asarray(jax.vmap(f)(q)),
                               rtol=1e-12, atol=1e-12)
    bad = q.copy()
    bad[37, 2] = np.nan  # in the third chunk of 16
    with pytest.raises(jflex.DataError, match=r"aba: q contains NaN/inf \(batch item 37"):
        jflex.sweep(f, bad, chunk_size=16, progress=False)


def test_flagged_vmap_holds_no_callback_and_names_the_failed_row(arm, tmp_path):
    from jflex._sweep import flagged_vmap

    robot, model = arm
    rows = flagged_vmap(lambda r, q, v, a: jflex.rnea(r, q, v, a), in_axes=(None, 0, 0, 0))
    q, v, a = np.random.default_rng(3).uniform(-1, 1, (3, 12, robot.nq))
    data = model.createData()
    ref = np.array([pin.rnea(model, data, q[i], v[i], a[i]) for i in range(12)])
    np.testing.assert_allclose(np.asarray(rows(robot, q, v, a)), ref, rtol=1e-10, atol=1e-10)
    bad = v.copy()
    bad[7, 0] = np.inf
    with pytest.raises(jflex.DataError, match=r"rnea: qd contains NaN/inf \(batch item 7"):
        rows(robot, q, bad, a)
    # JAX's persistent cache stores it (it stores no program with a callback into Python)
    import subprocess
    import sys

    code = f"""
import numpy as np, jax, jflex, logging, sys
sys.path.insert(0, {str(pathlib.Path(__file__).parent)!r})
from test_batched_checks import ARM
from jflex._sweep import flagged_vmap
jflex.enable_compilation_cache({str(tmp_path)!r}, min_compile_time_s=0.0)
robot = jflex.from_urdf_string(ARM, name="arm")
rows = flagged_vmap(lambda r, q, v, a: jflex.rnea(r, q, v, a), in_axes=(None, 0, 0, 0))
q = np.zeros((4, robot.nq))
rows(robot, q, q, q)
print("OK")
"""
    for _ in range(2):
        res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
        assert res.returncode == 0 and "OK" in res.stdout, res.stderr[-2000:]
    assert any(tmp_path.rglob("*jit_program*"))
