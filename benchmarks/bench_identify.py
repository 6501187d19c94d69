"""Benchmark: multi-posture FRF fit of 6 joint parameters (K, C of three flexible joints).

optimistix Levenberg-Marquardt with exact (forward-mode AD) Jacobians against
``scipy.optimize.least_squares`` with finite-difference Jacobians, on the same jitted residual
and the same start (+/-50 % off the planted values). Not a test: run it and read the table.

    python benchmarks/bench_identify.py [--postures 5] [--freqs 120] [--repeat 3]
"""

from __future__ import annotations

import argparse
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import scipy.optimize

import jflex
from jflex import identify as idf


def _robot():
    rng = np.random.default_rng(0)
    inert = []
    for _ in range(3):
        J = rng.uniform(0.02, 0.5, size=3)
        inert.append({"mass": float(rng.uniform(20, 80)), "com": (rng.normal(size=3) * 0.2).tolist(),
                      "inertia": [J[1] + J[2], 0.0, J[0] + J[2], 0.0, 0.0, J[0] + J[1]]})
    return jflex.from_dh([[0, 0, 0.642, 0], [np.pi / 2, 0.25, 0, 0], [0, 0.95, 0, 0]], tool=[0, 0.994, 0, 0], inertias=inert)


def _model(robot, K, C):
    return jflex.Model(robot, [jflex.effects.FlexibleJoints(K, C, rotor_inertia=[1e-3] * 3, gear_ratio=[100.0] * 3, coupling=False)])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--postures", type=int, default=5)
    ap.add_argument("--freqs", type=int, default=120)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args(argv)
    robot = _robot()
    K, C = np.array([2e5, 5e5, 1.5e5]), np.array([300.0, 100.0, 150.0])
    true = _model(robot, K, C)
    rng = np.random.default_rng(1)
    post = np.column_stack([rng.uniform(-1, 1, a.postures), rng.uniform(0.2, 1.4, a.postures), rng.uniform(-2, -0.3, a.postures)])
    omega = 2 * np.pi * np.linspace(2, 60, a.freqs)
    H = jax.jit(jax.vmap(lambda q: jflex.frf(true, q, omega, hold="actuated", frame="tool")))(jnp.asarray(post))
    data = idf.FRFData(post, omega, np.asarray(H), frame="tool")
    spec = idf.ParameterSpec([idf.Free("K", lambda m: m.effects[0].stiffness, transform=idf.Log()),
                              idf.Free("C", lambda m: m.effects[0].damping, transform=idf.Log())]).bind(true)
    start = _model(robot, K * [1.5, 0.5, 1.5], C * [0.5, 1.5, 0.5])
    u0 = spec.pack(start)
    truth = np.log(np.concatenate([K, C]))

    def resid(u, args=None):
        return idf.residual_vector(spec.apply(start, u), data)

    r_jit = jax.jit(resid)
    optx_rows = []
    for label, solver in [("optimistix LM, exact AD Jacobian (jit)", optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10)),
                          ("jflex LM (expand at 0.75), exact AD Jacobian", idf.levenberg_marquardt(rtol=1e-10, atol=1e-10))]:
        solve = eqx.filter_jit(lambda u, solver=solver: (lambda s: (s.value, s.stats["num_steps"]))(
            optx.least_squares(resid, solver, u, max_steps=200, throw=False)))
        t0 = time.perf_counter()
        sol = solve(u0)
        jax.block_until_ready(sol)
        compile_optx = time.perf_counter() - t0
        times = []
        for _ in range(a.repeat):
            t0 = time.perf_counter()
            sol = solve(u0)
            jax.block_until_ready(sol)
            times.append(time.perf_counter() - t0)
        optx_rows.append((label, min(times), int(sol[1]), float(np.abs(np.asarray(sol[0]) - truth).max()), compile_optx))

    t0 = time.perf_counter()
    np.asarray(r_jit(u0))
    compile_res = time.perf_counter() - t0
    calls = [0]

    def fun(u):
        calls[0] += 1
        return np.asarray(r_jit(jnp.asarray(u)))

    times = []
    for _ in range(a.repeat):
        calls[0] = 0
        t0 = time.perf_counter()
        ls = scipy.optimize.least_squares(fun, np.asarray(u0), method="lm", xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=5000)
        times.append(time.perf_counter() - t0)
    t_sp = min(times)
    err_sp = float(np.abs(ls.x - truth).max())
    # Counted here: MINPACK's nfev leaves out the n residual calls of each finite-difference Jacobian.
    iters_sp, evals_sp = ls.nfev, calls[0]

    print(f"multi-posture FRF fit: {a.postures} postures x {a.freqs} frequencies x 3x3 tool FRF, 6 parameters")
    print(f"{'solver':44s} {'time [s]':>10s} {'iterations':>11s} {'residual evals':>15s} {'max |u - u_true|':>17s}")
    for label, t, steps, err, _ in optx_rows:
        print(f"{label:44s} {t:10.3f} {steps:11d} {f'{steps} + {steps} Jac':>15s} {err:17.2e}")
    print(f"{'scipy least_squares lm, FD Jacobian':44s} {t_sp:10.3f} {iters_sp:11d} {evals_sp:15d} {err_sp:17.2e}")
    for label, t, steps, _, comp in optx_rows:
        print(f"ratio scipy / {label}: time {t_sp / t:.2f}x, iterations {iters_sp / max(steps, 1):.2f}x (compile {comp:.1f} s, not in the times)")
    print(f"(compile of the residual for scipy {compile_res:.1f} s; not in the times)")
    t_optx, steps_optx = optx_rows[0][1], optx_rows[0][2]
    return dict(t_optx=t_optx, t_scipy=t_sp, steps_optx=steps_optx, iters_scipy=iters_sp)


if __name__ == "__main__":
    main()
