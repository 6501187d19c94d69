"""Traced programs kept on disk: a second process reads the program instead of tracing the kernel
(counted by calls into the traversal while tracing, not timed), gets the same numbers, and uses a
stored program only when every input to the trace is the same; a damaged entry is never used."""

import hashlib
import json
import os
import subprocess
import sys

import numpy as np
import pytest

import jflex
import jflex._program_cache as pc

ARM = """
import numpy as np, jax, jflex
import jflex._dynamics as dyn
from jflex._sweep import flagged_vmap
traces = []
core = dyn._rnea_core
dyn._rnea_core = lambda *a: (traces.append(1), core(*a))[1]  # runs only while JAX traces
jflex.enable_compilation_cache({folder!r}, min_compile_time_s=0.0)
import pathlib
robot = jflex.load_robot(str(pathlib.Path(jflex.__file__).parent / "data" / "demo_case" / "robot.yaml"))
rows = flagged_vmap(jflex.rnea, in_axes=(None, 0, 0, 0))
rng = np.random.default_rng(0)
q, v, a = rng.normal(size=(3, 6, robot.nq))
out = np.asarray(rows(robot, q, v, a))
ref = np.array([np.asarray(jflex.rnea(robot, q[i], v[i], a[i])) for i in range(6)])
print(json.dumps({{"traces": len(traces), "out": out.tolist(), "err": float(np.abs(out - ref).max())}}))
"""


def demo_robot():
    import pathlib

    return jflex.load_robot(str(pathlib.Path(jflex.__file__).parent / "data" / "demo_case" / "robot.yaml"))


def run(folder):
    code = "import json\n" + ARM.format(folder=str(folder))
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                         env=dict(os.environ, JFLEX_NO_CACHE="1"))
    assert res.returncode == 0, res.stderr[-3000:]
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_a_second_process_reads_the_program_instead_of_tracing(tmp_path):
    first = run(tmp_path)
    stored = sorted((tmp_path / "jflex-programs").glob("*.jfx"))
    assert first["traces"] >= 1 and len(stored) == 1 and first["err"] < 1e-12
    second = run(tmp_path)
    # the plain reference calls still trace rnea (outside the cached program): one trace fewer
    assert second["traces"] == first["traces"] - 1
    assert second["out"] == first["out"]
    # a damaged entry fails its checksum: traced and stored again, same numbers
    blob = bytearray(stored[0].read_bytes())
    blob[-100] ^= 0xFF
    stored[0].write_bytes(bytes(blob))
    third = run(tmp_path)
    assert third["traces"] == first["traces"] and third["out"] == first["out"]
    assert run(tmp_path)["traces"] == second["traces"]  # rewritten whole


def key_of(fn, *args):
    import equinox as eqx
    import jax

    dynamic, static = eqx.partition(args, eqx.is_array)
    leaves, treedef = jax.tree_util.tree_flatten(dynamic)
    return pc._key(fn, static, treedef, tuple(pc._aval(x) for x in leaves))


def test_the_key_sees_every_input_of_the_trace(monkeypatch):
    robot = demo_robot()
    q = np.zeros((4, robot.nq))
    base = key_of(jflex.rnea, robot, q, q, q)
    assert base is not None and base == key_of(jflex.rnea, demo_robot(), q, q, q)
    assert key_of(jflex.crba, robot, q) != key_of(jflex.gravity, robot, q)
    assert key_of(jflex.rnea, robot, q[:3], q[:3], q[:3]) != base  # shapes
    assert key_of(jflex.rnea, robot, q.astype(np.float32), q, q) != base  # dtypes
    import copy

    renamed = copy.copy(robot)
    object.__setattr__(renamed, "joint_names", ("a", "b", "c"))  # a static field
    assert key_of(jflex.rnea, renamed, q, q, q) != base
    heavier = robot.replace(inertia=robot.inertia * 2)  # same shapes: the same program
    assert key_of(jflex.rnea, heavier, q, q, q) == base
    # numbers closed over are constants of the program: part of the key
    import functools

    assert key_of(functools.partial(jflex.rnea, robot), q, q, q) != key_of(functools.partial(jflex.rnea, heavier), q, q, q)
    from jflex._trig import vectorised

    with vectorised():  # a trace-time mode of jflex
        assert key_of(jflex.rnea, robot, q, q, q) != base
    # code outside jflex, JAX, NumPy and equinox is not covered by the key: never stored
    assert key_of(lambda r, a: jflex.crba(r, a), robot, q) is None
    import types

    assert key_of(jflex.rnea, types.SimpleNamespace(r=robot), q, q, q) is None
    # another version of jflex's sources
    monkeypatch.setattr(pc, "_environment", lambda: hashlib.sha256(b"other sources").digest())
    assert key_of(jflex.rnea, robot, q, q, q) != base


def test_without_a_folder_or_with_traced_arguments_it_is_filter_jit(tmp_path, monkeypatch):
    import jax

    calls = []

    def double(x, scale):
        calls.append(1)
        return {"y": 2.0 * x * scale, "label": "double"}

    prog = pc.persistent_jit(double)
    x = np.arange(3.0)
    assert prog(x, 1.5)["label"] == "double"
    monkeypatch.setattr(pc, "_FOLDER", tmp_path)
    out = prog(x, 1.5)  # a function of this test module: not keyable, traced as before
    np.testing.assert_allclose(out["y"], 3.0 * x)
    assert not any(tmp_path.iterdir())
    np.testing.assert_allclose(jax.jit(lambda z: prog(z, 1.5)["y"])(x), 3.0 * x)


def test_outputs_come_back_in_their_containers(tmp_path, monkeypatch):
    monkeypatch.setattr(pc, "_FOLDER", tmp_path)
    robot = demo_robot()
    from jflex._sweep import flagged_vmap

    rows = flagged_vmap(jflex.crba, in_axes=(None, 0))
    q = np.random.default_rng(1).normal(size=(5, robot.nq))
    out = rows(robot, q)
    ref = np.array([np.asarray(jflex.crba(robot, qi)) for qi in q])
    np.testing.assert_allclose(np.asarray(out), ref, rtol=1e-12, atol=1e-12)
    assert len(list(tmp_path.glob("*.jfx"))) == 1
    pc._LOADED.clear()
    again = flagged_vmap(jflex.crba, in_axes=(None, 0))(robot, q)  # a new function object: read back
    np.testing.assert_array_equal(np.asarray(again), np.asarray(out))
    bad = q.copy()
    bad[3, 1] = np.nan
    with pytest.raises(jflex.DataError, match="batch item 3"):  # the checks' flags still come back
        rows(robot, bad)
