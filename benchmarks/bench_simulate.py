"""Time responses: jflex.simulate (diffrax, jit) against scipy.integrate.solve_ivp on the same
right-hand side written with NumPy + Pinocchio, one process, same tolerance. Not a test: prints a
table with times and ratios.

System: a 6-joint arm (PUMA-like DH table) with a flexible joint at every axis (issue 3's
``jflex.effects.FlexibleJoints``, reduced model: motor inertia J, spring K between motor and link),
released from rest at a bent posture under gravity for ``--t-end`` seconds (no input).

1. One response: jflex Tsit5 (after compile) vs solve_ivp RK45 with ``pin.aba`` in the RHS, both at
   rtol/atol given; the final states are compared.
2. A batch of ``--batch`` responses from perturbed initial postures: jflex ``jax.vmap`` of the
   whole solve vs solve_ivp in a Python loop (timed on ``--baseline-n`` of them, extrapolated).

    python benchmarks/bench_simulate.py [--t-end 10] [--batch 1000] [--baseline-n 5] [--rtol 1e-6]
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import time

p = argparse.ArgumentParser()
p.add_argument("--t-end", type=float, default=10.0)
p.add_argument("--batch", type=int, default=1000)
p.add_argument("--baseline-n", type=int, default=5)
p.add_argument("--rtol", type=float, default=1e-6)
p.add_argument("--atol", type=float, default=1e-8)
args = p.parse_args()

import diffrax  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

import jflex  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))
from _references import pin_model_from_robot  # noqa: E402

TABLE = [[0, 0, 0.0, 0], [-np.pi / 2, 0, 0.0, 0], [0, 0.43, 0.15, 0], [-np.pi / 2, 0.02, 0.43, 0],
         [np.pi / 2, 0, 0, 0], [-np.pi / 2, 0, 0, 0]]
MASS = [4.0, 17.4, 4.8, 0.82, 0.34, 0.09]
robot = jflex.from_dh(TABLE, inertias=[{"mass": m, "com": [0.05, 0.02, 0.05], "inertia": [0.05 * m, 0, 0.05 * m, 0, 0, 0.03 * m]} for m in MASS])
K = np.array([4000.0, 6000.0, 3000.0, 500.0, 400.0, 300.0])
J = np.array([1.0, 1.5, 0.8, 0.1, 0.1, 0.05])  # reflected rotor inertias r^2 I_m [kg m^2]
model = jflex.Model(robot, [jflex.effects.FlexibleJoints(K, rotor_inertia=J, coupling=False)])
n = 6
q0 = np.array([0.1, -0.6, 0.4, 0.2, -0.3, 0.1])
x0 = np.concatenate([q0, q0])  # motors aligned with links: the springs are unloaded, gravity pulls

pmodel = pin_model_from_robot(robot)
pdata = pmodel.createData()


def rhs(t, y):
    q, th, qd, thd = y[:n], y[n:2 * n], y[2 * n:3 * n], y[3 * n:]
    spring = K * (th - q)
    qdd = pin.aba(pmodel, pdata, q, qd, spring)
    thdd = -spring / J
    return np.concatenate([qd, thd, qdd, thdd])


def scipy_run(x0_):
    y0 = np.concatenate([x0_, np.zeros(2 * n)])
    return solve_ivp(rhs, (0.0, args.t_end), y0, method="RK45", rtol=args.rtol, atol=args.atol, t_eval=[args.t_end])


ts = jnp.array([0.0, args.t_end])


def jflex_run(x0_):
    r = jflex.simulate(model, ts, x0=x0_, rtol=args.rtol, atol=args.atol, outputs=("x",), max_steps=1_000_000,
                       solver=diffrax.Tsit5())
    return r["x"][-1], r.num_steps


one = jax.jit(jflex_run)
t = time.perf_counter()
xf, steps = jax.block_until_ready(one(jnp.asarray(x0)))
compile_s = time.perf_counter() - t
reps = 3
t = time.perf_counter()
for _ in range(reps):
    jax.block_until_ready(one(jnp.asarray(x0)))
jflex_one = (time.perf_counter() - t) / reps

t = time.perf_counter()
sol = scipy_run(x0)
scipy_one = time.perf_counter() - t
diff = float(np.max(np.abs(np.asarray(xf) - sol.y[: 2 * n, -1])))

rng = np.random.default_rng(0)
X0 = x0[None, :] + np.concatenate([rng.normal(scale=0.05, size=(args.batch, n))] * 2, axis=1)
batch = jax.jit(jax.vmap(jflex_run))
t = time.perf_counter()
xb, sb = jax.block_until_ready(batch(jnp.asarray(X0)))
jflex_batch_first = time.perf_counter() - t  # includes the compile
t = time.perf_counter()
jax.block_until_ready(batch(jnp.asarray(X0)))
jflex_batch = time.perf_counter() - t
t = time.perf_counter()
for i in range(args.baseline_n):
    scipy_run(X0[i])
scipy_per = (time.perf_counter() - t) / args.baseline_n

print(f"6-joint flexible-joint arm, {args.t_end:g} s response, rtol {args.rtol:g}, atol {args.atol:g}; "
      f"jax {jax.__version__}, {jax.devices()[0].platform}")
print(f"{'case':44s} {'jflex [s]':>11s} {'scipy [s]':>11s} {'scipy/jflex':>12s}")
print(f"{'one response (jit, after compile)':44s} {jflex_one:11.3f} {scipy_one:11.3f} {scipy_one / jflex_one:12.2f}")
print(f"{f'batch of {args.batch} (vmap; scipy extrapolated)':44s} {jflex_batch:11.3f} {scipy_per * args.batch:11.3f} "
      f"{scipy_per * args.batch / jflex_batch:12.2f}")
print(f"per response in the batch: jflex {1e3 * jflex_batch / args.batch:.2f} ms, scipy {1e3 * scipy_per:.1f} ms")
print(f"jflex compile: one {compile_s:.1f} s, batch (compile + first run) {jflex_batch_first:.1f} s; steps: jflex {int(steps)}, scipy {sol.nfev // 6} (nfev/6); "
      f"max |x_jflex - x_scipy| at t_end = {diff:.2e}")
