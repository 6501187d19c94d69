"""The persistent compilation cache: one process compiles and stores, a second process finds
the stored programs and loads them instead of compiling (JAX's cache-hit events, not timing)."""

import json
import os
import subprocess
import sys

import pytest

import jflex

CODE = """
import json, jax, jax.numpy as jnp
import jflex
from jax import monitoring
events = []
monitoring.register_event_listener(lambda name, **kw: events.append(name))
jax.jit(lambda x: x * 2.0)(1.0)  # compiled before the cache is on: not stored
folder = jflex.enable_compilation_cache(min_compile_time_s=0)
r = jflex.load_robot("staubli_tx200")
r = r.replace(inertia=jnp.tile(jnp.array([5.0, 0.5, 0.1, 0.2, 1.0, 0.0, 1.0, 0.0, 0.0, 1.0]), (r.nq, 1)))
out = jax.jit(lambda q: jflex.crba(r, q))(jnp.ones(r.nq))
print(json.dumps({"folder": str(folder),
                  "hits": events.count("/jax/compilation_cache/cache_hits"),
                  "misses": events.count("/jax/compilation_cache/cache_misses"),
                  "M00": float(out[0, 0])}))
"""


def run_once(env):
    res = subprocess.run([sys.executable, "-c", CODE], env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_a_second_process_loads_what_the_first_compiled(tmp_path):
    folder = tmp_path / "moved" / "cache"
    env = dict(os.environ, JFLEX_CACHE_DIR=str(folder))
    first = run_once(env)
    assert first["folder"] == str(folder)
    assert first["hits"] == 0 and first["misses"] >= 1
    stored = sorted(p.name for p in folder.iterdir())
    assert stored, "nothing was written to the cache folder"
    second = run_once(env)
    assert second["hits"] >= first["misses"] and second["misses"] == 0
    assert second["M00"] == first["M00"]
    assert sorted(p.name for p in folder.iterdir()) == stored  # nothing new compiled


def test_a_file_is_refused_as_cache_folder(tmp_path):
    f = tmp_path / "file"
    f.write_text("")
    with pytest.raises(jflex.ConfigError, match="path.*file"):
        jflex.enable_compilation_cache(f)


def test_default_folder_follows_the_environment(monkeypatch, tmp_path):
    from jflex._compilation_cache import default_cache_dir

    monkeypatch.setenv("JFLEX_CACHE_DIR", str(tmp_path / "x"))
    assert default_cache_dir() == tmp_path / "x"
    monkeypatch.delenv("JFLEX_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert default_cache_dir() == tmp_path / "xdg" / "jflex" / "jax"
