"""The sweep helper (sharding on 4 host devices, chunk files, resume) and the CLI convention."""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import jflex

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_sweep_shards_over_four_host_devices(tmp_path):
    code = textwrap.dedent(
        f"""
        import jax, numpy as np, jflex
        assert len(jax.devices()) == 4, jax.devices()
        r = jflex.load_robot("staubli_tx200")
        r = r.replace(inertia=np.tile([5.0, 0.5, 0.1, 0.2, 1.0, 0.0, 1.0, 0.0, 0.0, 1.0], (3, 1)))
        q = np.random.default_rng(0).normal(size=(1003, 3))
        seen = []
        out = jflex.sweep(lambda x: jflex.crba(r, x), q, chunk_size=200, out_dir=r"{tmp_path}",
                          on_chunk=lambda a, b, o: seen.append((a, b)), progress=False, devices=jax.devices())
        ref = np.stack([np.asarray(jflex.crba(r, x)) for x in q[:50]])
        assert out.shape == (1003, 3, 3)
        assert np.abs(out[:50] - ref).max() < 1e-12
        assert seen[-1][1] == 1003 and len(seen) == 6, seen
        print("OK")
        """
    )
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4")
    res = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    assert (tmp_path / "chunk_000000000.npz").exists()


def test_batched_splits_over_two_host_devices():
    """``batched(devices=...)`` (how a batch uses two cores on CPU) gives the one-device results,
    fused and unfused, on a batch that does not divide evenly."""
    code = textwrap.dedent(
        """
        import jax, numpy as np, jflex
        assert len(jax.devices()) == 2, jax.devices()
        r = jflex.load_robot("staubli_tx200")
        r = r.replace(inertia=np.tile([5.0, 0.5, 0.1, 0.2, 1.0, 0.0, 1.0, 0.0, 0.0, 1.0], (3, 1)))
        rng = np.random.default_rng(0)
        q, v, t = (rng.normal(size=(1001, r.nq)) for _ in range(3))
        f = lambda q, v, t: jflex.rnea(r, q, v, t)
        ref = np.asarray(jflex.batched(f)(q, v, t))
        for fuse in (True, False):
            out = jflex.batched(f, batch_size=128, fuse=fuse, devices=jax.devices())(q, v, t)
            assert out.shape == ref.shape and len(out.sharding.device_set) == 2, out.sharding
            assert np.abs(np.asarray(out) - ref).max() < 1e-9 * np.abs(ref).max()
        print("OK")
        """
    )
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2")
    res = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]


def test_sweep_uses_one_cpu_device_per_process_by_default():
    """With two CPU devices in one process, a sweep over a Cholesky solve (jaxlib's batched
    LAPACK kernels, which could deadlock split over both) runs on one device by default and
    finishes with the plain results."""
    code = textwrap.dedent(
        """
        import jax, numpy as np, jflex
        from jflex._sweep import _default_devices
        assert len(jax.devices()) == 2, jax.devices()
        assert _default_devices() == jax.devices()[:1], _default_devices()
        r = jflex.load_robot("staubli_tx200")
        r = r.replace(inertia=np.tile([5.0, 0.5, 0.1, 0.2, 1.0, 0.0, 1.0, 0.0, 0.0, 1.0], (3, 1)))
        rng = np.random.default_rng(0)
        q, v, t = (rng.normal(size=(4000, r.nq)) for _ in range(3))
        f = lambda q, v, t: jflex.forward_dynamics(r, q, v, t, method="crba")
        ref = np.asarray(jax.jit(jax.vmap(f))(q, v, t))
        for _ in range(8):
            out = jflex.sweep(f, q, v, t, chunk_size=4000, progress=False)
        assert np.abs(out - ref).max() < 1e-9 * np.abs(ref).max()
        print("OK")
        """
    )
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2")
    res = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]


def test_sweep_resumes_from_saved_chunks(tmp_path):
    calls = []

    def fn(x):
        return x * 2.0

    q = np.arange(10.0)[:, None]
    first = jflex.sweep(fn, q, chunk_size=4, out_dir=tmp_path, progress=False)
    # plant other values in chunk 4 (its fingerprint kept): the resumed sweep must read them from disk
    with np.load(tmp_path / "chunk_000000004.npz") as d:
        saved = dict(d)
    saved["leaf0"] = saved["leaf0"] + 100.0
    np.savez(tmp_path / "chunk_000000004.npz", **saved)
    second = jflex.sweep(fn, q, chunk_size=4, out_dir=tmp_path, progress=False,
                         on_chunk=lambda a, b, o: calls.append(a))
    np.testing.assert_allclose(first, 2.0 * q)
    np.testing.assert_allclose(second[4:8], 2.0 * q[4:8] + 100.0)
    assert calls == [0, 4, 8]
    # another function in the same folder is refused, never served stale chunks (tests/test_sweep_resume.py)
    with pytest.raises(jflex.DataError, match="different sweep"):
        jflex.sweep(lambda x: x * 3.0, q, chunk_size=4, out_dir=tmp_path, progress=False)


def test_sweep_rejects_mismatched_batch():
    with pytest.raises(jflex.ShapeError, match="leading axis"):
        jflex.sweep(lambda a, b: a + b, np.zeros((3, 2)), np.zeros((4, 2)))


def test_cli_info_and_demo(tmp_path, capsys):
    import time

    from jflex.cli import main

    assert main(["info", "staubli_tx200"]) == 0
    out = tmp_path / "demo"
    cfg = tmp_path / "demo.yaml"
    cfg.write_text(open(os.path.join(ROOT, "configs", "demo.yaml")).read().replace("n: 61", "n: 9"))
    t0 = time.perf_counter()
    assert main(["demo", str(cfg), "--out", str(out)]) == 0
    wall = time.perf_counter() - t0
    # how much of the run was tracing and compiling: said on stderr and kept beside the results,
    # within the wall time this test measured around the command
    clock = json.loads((out / "compile_time.json").read_text())
    assert 0 < clock["tracing_and_compiling_s"] <= clock["wall_s"] <= wall and clock["programs"] >= 1
    assert "tracing and compiling" in capsys.readouterr().err
    res = json.loads((out / "results.json").read_text())
    assert res and all((out / p).exists() for p in res.get("plots", []))
    # the rigid maps are of the robot diagnosed (the demo case's 3-joint arm), not another one
    assert res["rigid_maps"]["robot"].startswith("arm3") and "diagnosed" in res["rigid_maps"]["robot"]


def test_cli_reports_bad_robot_cleanly(capsys):
    from jflex.cli import main

    assert main(["info", "no_such_robot"]) == 2
    assert "unknown robot 'no_such_robot'" in capsys.readouterr().err


def test_every_experiment_runs_under_jflex_run():
    # `jflex run NAME` calls main(argv) of experiments/NAME.py
    import ast

    import pathlib

    root = pathlib.Path(ROOT) / "experiments"
    for path in sorted(root.glob("*.py")):
        if path.name.startswith("_"):
            continue  # a module the experiments share, which `jflex run` does not list
        tree = ast.parse(path.read_text())
        assert any(isinstance(n, ast.FunctionDef) and n.name == "main" for n in tree.body), f"{path.name}: no main(argv)"
