"""Benchmark: seed-004 hysteretic damping fit (tip free vibration of the rigid-flexible arm).

jflex (``jflex.identify.fit`` with ``jflex.identify.levenberg_marquardt``: residual and exact
Jacobian from one forward-mode solve through ``jflex.simulate`` per step) against
``scipy.optimize.least_squares`` (MINPACK Levenberg-Marquardt by default) with finite-difference
Jacobians calling the SAME jitted residual, from the SAME start, with the same stopping tolerance,
in one process. Not a test: run it and read the table.

The arm, the planted record (hysteretic law at Table V's values + 1 % noise, travel-driven
reversal) and the free parameters (log k_e h0, log delta) are those of
``experiments/identify_seed004.py`` / ``configs/identify_seed004.yaml`` (imported, not copied);
only the record is shortened (``--t-end``, ``--samples``: the same 100 Hz grid and, because the
random generator is consumed in the experiment's order, the same noise as the first seconds of
the experiment's record) and there is no multistart and no continuation: one local fit from the
config's start (+50 % h0, -50 % delta), at the config's fit tolerances (rtol 1e-5).

Counting: a jflex step is one trial point, evaluated with its Jacobian in one forward-mode solve
(2 tangents); ``--max-iter`` caps jflex's steps and scipy's trial points (``max_nfev``, which for
MINPACK leaves out the finite-difference calls). "residual evals" counts solves: jflex's
residual+Jacobian solves, scipy's calls of the residual (trial points + 2 per FD Jacobian).
scipy runs once per ``--diff-step``: its default relative step (~1.5e-8) is far below the
noise that the adaptive solve at rtol 1e-5 puts on the residual, so its Jacobian is mostly that
noise; 1e-3 (about sqrt(rtol)) is the step a user would pick for such a residual.
Times: best of ``--repeat``; compile time excluded and printed separately (jflex's fit compiles
its residual+Jacobian on every call: its compile is the time to the first step minus one
steady-state evaluation).

    python benchmarks/bench_identify_seed004.py [--samples 150] [--t-end 1.5] [--max-iter 20] [--repeat 1] [--diff-step default 1e-3]
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
import scipy.optimize

import jflex
from jflex import identify as idf

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "experiments"))
import identify_seed004 as exp  # noqa: E402  (the experiment: arm, record, laws)


def _jflex_fit(model, spec, data, solver, max_iter, stall):
    """One jflex fit; returns (result, total s, s excluding compile, compile s)."""
    stamps = []
    t0 = time.perf_counter()
    res = idf.fit(model, spec, data, solver, max_steps=max_iter, progress=False, stall=stall,
                  callback=lambda k, c, v: stamps.append(time.perf_counter()))
    tm = res.timing
    total = tm["total_s"]
    later = tm["jacobian_evals"] - 1
    mean_eval = tm["jacobian_run_s"] / later if later > 0 else float("nan")
    # the first step's stamp comes after: compile + first evaluation + the LM step's own compile
    run = (stamps[-1] - stamps[0]) + mean_eval if stamps else float("nan")
    return res, total, run, (stamps[0] - t0) - mean_eval if stamps else float("nan"), mean_eval


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(exp.DEFAULT))
    ap.add_argument("--samples", type=int, default=150)
    ap.add_argument("--t-end", type=float, default=1.5)
    ap.add_argument("--max-iter", type=int, default=20)
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--method", default="lm", choices=["lm", "trf"], help="scipy least_squares method")
    ap.add_argument("--diff-step", nargs="+", default=["default", "1e-3"],
                    help="scipy's relative finite-difference steps, one row each ('default': scipy's, ~1.5e-8)")
    ap.add_argument("--weak-start", action="store_true",
                    help="leave the start model's free leaves as Python floats (jflex then recompiles once; timed as run time)")
    a = ap.parse_args(argv)

    cfg = jflex.load_yaml(a.config)
    cfg = {**cfg, "t_end_s": a.t_end, "samples": a.samples}
    arm_cfg = jflex.load_yaml(ROOT / "configs" / cfg["arm"])
    rng = np.random.default_rng(0)
    exp.static_deflection(cfg, arm_cfg, rng)  # consumes the generator as the experiment does
    t0 = time.perf_counter()
    data, _, info = exp.record(cfg, arm_cfg, rng)
    t_record = time.perf_counter() - t0
    law, frees, _ = exp.laws(cfg, arm_cfg)["hysteretic"]
    h = arm_cfg["damping"]["hysteretic"]
    ke_h, h0_true, delta_true = float(h["k_e"]), float(h["h0_N"]), float(h["delta_m"])
    model = exp.build(arm_cfg, law)
    spec = idf.ParameterSpec(frees).bind(model)
    if not a.weak_start:
        # The law's leaves are Python floats, so fit's start vector would be weak-typed and its
        # residual+Jacobian would compile a second time (~16 s) at the first evaluation after the
        # start (the solver's points are strongly typed): give the free leaves float64 arrays.
        for f in spec.frees:
            model = f.set(model, jnp.asarray(f.get(model), dtype=jnp.float64))
    u0 = np.asarray(spec.pack(model), dtype=float)  # scipy's start; the jitted residual compiles for it
    tol = float(cfg["lm_tol"])
    stall = cfg.get("stall")
    solver = idf.levenberg_marquardt(tol, tol)

    # the residual both solvers minimise (fit's own residual: the same data residuals, no priors)
    @jax.jit
    def r_jit(u):
        return idf.residual_vector(spec.apply(model, u), data)

    def cost(u):
        return 0.5 * float(jnp.sum(r_jit(jnp.asarray(u)) ** 2))

    def physical(u):
        v = spec.values(jnp.asarray(u))
        return float(v["k_e_h0_N"]) / ke_h, float(v["delta_m"])

    # --- jflex -----------------------------------------------------------------------------------
    jf = []
    for _ in range(a.repeat):
        jf.append(_jflex_fit(model, spec, data, solver, a.max_iter, stall))
    res, total_j, t_j, comp_j, eval_j = min(jf, key=lambda x: x[2])
    u_j = np.asarray(res.u)
    evals_j = res.timing["jacobian_evals"]

    # --- scipy, finite differences on the same jitted residual --------------------------------------
    t0 = time.perf_counter()
    c0 = cost(u0)
    comp_s = time.perf_counter() - t0
    calls = [0]

    def fun(u):
        calls[0] += 1
        return np.asarray(r_jit(jnp.asarray(u)))

    n = u0.shape[0]
    sp_rows = []  # (label, time, result, calls, Jacobians)
    for ds in a.diff_step:
        step = None if ds.lower() == "default" else float(ds)
        runs = []
        for _ in range(a.repeat):
            calls[0] = 0
            t0 = time.perf_counter()
            ls = scipy.optimize.least_squares(fun, u0, method=a.method, xtol=tol, ftol=tol, gtol=tol,
                                              max_nfev=a.max_iter, diff_step=step)
            runs.append((time.perf_counter() - t0, ls, calls[0]))
        t_s, ls, evals_s = min(runs, key=lambda x: x[0])
        jac_s = ls.njev if ls.njev is not None else (evals_s - ls.nfev) // n
        sp_rows.append((f"scipy {a.method}, FD Jacobian, diff_step {ds}", t_s, ls, evals_s, jac_s))
    t0 = time.perf_counter()
    for _ in range(3):
        fun(np.asarray(u0))
    t_fun = (time.perf_counter() - t0) / 3

    # --- table -------------------------------------------------------------------------------------
    cj = cost(u_j)
    kw = dict(data.simulate_kw)
    h0_j, d_j = physical(u_j)
    h0_0, d_0 = physical(u0)
    print(f"seed-004 hysteretic fit: {info['samples']} samples over {info['t_end_s']:g} s, noise std "
          f"{info['noise_std_m']:.3e} m (NRMSE floor {info['noise_nrmse_floor']:.4f}), fit rtol {kw['rtol']:g}, "
          f"atol {kw['atol']:g}; record made in {t_record:.1f} s")
    print(f"start: h0 {h0_0:.4g} N ({100 * (h0_0 / h0_true - 1):+.0f} %), delta {d_0:.4g} m ({100 * (d_0 / delta_true - 1):+.0f} %), "
          f"cost {c0:.6e} (jflex's own start cost, from its forward-mode solve: {res.history[0]:.6e}); "
          f"planted h0 {h0_true:g} N, delta {delta_true:g} m")
    print(f"stopping: rtol = atol = {tol:g} (jflex Cauchy; scipy xtol = ftol = gtol), at most {a.max_iter} trial points, "
          f"jflex stall {stall}; best of {a.repeat}; start leaves {'weak-typed (as built)' if a.weak_start else 'float64 arrays'}; "
          f"final costs from the same jitted residual (NRMSE = sqrt(2 cost))")
    hdr = (f"| {'solver':44s} | time [s] | compile [s] | iterations (trial points) | residual solves | final cost (NRMSE) "
           f"| rel. cost diff vs jflex | h0 [N] (vs planted) | delta [m] (vs planted) | stop |")
    print(hdr)
    print("|" + "|".join("-" * (len(c)) for c in hdr.split("|")[1:-1]) + "|")
    print(f"| {'jflex LM, exact forward-mode Jacobian':44s} | {t_j:8.1f} | {comp_j:11.1f} | {f'{res.steps} ({res.steps})':>25s} | "
          f"{f'{evals_j} r+J':>15s} | {cj:.6e} ({np.sqrt(2 * cj):.3f}) | {0.0:+.3e} | {h0_j:.5f} ({100 * (h0_j / h0_true - 1):+.2f} %) | "
          f"{d_j:.4e} ({100 * (d_j / delta_true - 1):+.2f} %) | {res.result} |")
    for label, t_s, ls, evals_s, jac_s in sp_rows:
        cs = cost(ls.x)
        h0_s, d_s = physical(ls.x)
        print(f"| {label:44s} | {t_s:8.1f} | {comp_s:11.1f} | {f'{jac_s} ({ls.nfev})':>25s} | {evals_s:15d} | {cs:.6e} ({np.sqrt(2 * cs):.3f}) | "
              f"{(cs - cj) / cj:+.3e} | {h0_s:.5f} ({100 * (h0_s / h0_true - 1):+.2f} %) | "
              f"{d_s:.4e} ({100 * (d_s / delta_true - 1):+.2f} %) | status {ls.status}: {ls.message} |")
    for label, t_s, ls, evals_s, jac_s in sp_rows:
        print(f"ratio {label} / jflex: time {t_s / t_j:.2f}x, trial points {ls.nfev / max(res.steps, 1):.2f}x, "
              f"residual solves {evals_s / max(evals_j, 1):.2f}x")
    print("jflex cost per step (trial point; the best is kept): " + " ".join(f"{c:.4g}" for c in res.history))
    print(f"per evaluation: jflex residual+Jacobian {eval_j:.2f} s, residual alone {t_fun:.2f} s; jflex total incl. compile "
          f"{total_j:.1f} s")
    return dict(t_jflex=t_j, cost_jflex=cj, scipy=[(r[0], r[1], cost(r[2].x)) for r in sp_rows])


if __name__ == "__main__":
    main()
