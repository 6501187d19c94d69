"""Modal analysis by the newton solver in float32 (``JFLEX_X64=0``, as on a GPU for speed): its
convergence test allows the residual the working precision can reach, so it agrees with
``solver="eig"`` instead of reporting every posture as not converged."""

import os
import subprocess
import sys

CODE = """
import numpy as np, jax, jax.numpy as jnp, jflex
assert jnp.asarray(1.0).dtype == jnp.float32
r = jflex.load_robot("panda")
n = r.nq
model = jflex.Model(r, [jflex.effects.FlexibleJoints(jnp.full(n, 1e4), jnp.full(n, 5.0), jnp.full(n, 0.1),
                                                     jnp.full(n, 50.0))])
Q = jnp.asarray(np.random.default_rng(3).uniform(-1.0, 1.0, (8, n)), jnp.float32)
fn = lambda s: jax.jit(jax.vmap(lambda q: jflex.modal_analysis(model, q, hold="actuated", solver=s).frequency))
a, b = (np.sort(np.asarray(fn(s)(Q)), axis=1) for s in ("newton", "eig"))
print(float(np.abs(a - b).max() / np.abs(b).max()))
"""


def test_newton_modal_analysis_in_float32_agrees_with_eig():
    env = dict(os.environ, JFLEX_X64="0")
    res = subprocess.run([sys.executable, "-c", CODE], capture_output=True, text=True, timeout=600, env=env)
    assert res.returncode == 0, res.stderr[-3000:]
    assert float(res.stdout.strip().splitlines()[-1]) < 1e-4
