"""import jflex sets XLA's legacy-CPU-emitter flag only for the jaxlib releases that have it:
jaxlib 0.11 removed the flag, and XLA aborts the whole process on a flag it does not know."""

import subprocess
import sys

import jflex


def test_flag_only_for_jaxlib_releases_that_have_it(monkeypatch):
    for version, has in (("0.10.2", True), ("0.4.38", True), ("0.11.2", False), ("1.0.0", False)):
        monkeypatch.setattr(jflex._md, "version", lambda name, v=version: v)
        assert jflex._jaxlib_has_fusion_emitter_flag() is has, version


def test_a_fresh_import_runs_a_computation():
    # the flag set on import must be one the installed XLA accepts (an unknown one aborts)
    code = "import jflex, jax.numpy as jnp; print(float(jnp.ones(3).sum()))"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0 and res.stdout.strip() == "3.0", res.stderr[-2000:]
