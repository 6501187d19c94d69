"""Benchmark: multi-posture tool-FRF fit of 18 joint parameters (K, C, rotor inertia of a 6-joint UR5).

Exact-Jacobian least squares (``optx.least_squares`` with ``jflex.identify.levenberg_marquardt``,
optimistix's ``GaussNewton``, ``LevenbergMarquardt``, ``IndirectLevenbergMarquardt``, ``Dogleg``; the
whole solve jitted, the postures vmapped inside ``FRFData``) against ``scipy.optimize.least_squares``
with finite-difference Jacobians calling the SAME jitted residual, from the SAME start, with the
same stopping tolerance. Not a test: run it and read the table.

Two exact Jacobians (``SOLVER/JAC`` rows):

- ``fwd``: ``jax.jacfwd`` of the residual, through ``jflex.frf``'s own JVP (which reuses each
  frequency's inverse and contracts the DENSE tangents dK, dM, dC: generic, any parameter).
- ``structured``: the library's :func:`jflex.identify.sparse_frf_residual` (what
  ``jflex.identify.fit(..., jacobian="sparse")`` uses), the same residual function with a custom
  JVP that contracts ``dH = -Y dD X`` only over the entries where ``d(M, C, K)/du`` is non-zero (4
  per joint stiffness or damping, 1 per rotor inertia; values by forward-mode AD of the
  linearisation, the pattern found at build time; the result checked here against ``jax.jacfwd``
  at two points). Its primal IS the plain residual, so scipy's rows are unaffected.

Set-up: ``jflex.load_robot("ur5")`` (6 revolute joints, gravity as loaded) with
``FlexibleJoints(K, C, rotor_inertia=I_m, gear_ratio=100, coupling=False)`` on every joint; the
tool FRF at ``tool0``, ``components="full"`` (6x6: forces and moments in, translations and
rotations out; the translational block alone does not see joint 6, whose axis passes through
tool0), at ``--postures`` random postures and ``--freqs`` frequencies in 5-100 Hz. The motor side
is left FREE (``hold=()``): with ``hold="actuated"`` (the motor angles clamped, as in
``bench_identify.py``) and ``coupling=False`` the rotor inertia does not enter the FRF at all, so
it could not be fitted. The planted FRFs carry ``--noise`` (default 1 %) log-normal multiplicative
noise on magnitude and phase, so the minimum has a non-zero cost and "equal final cost" means
something. Free: log K (6), log C (6), log I_m (6); start ``--start-offset`` (default 50 %) off the
truth, alternating signs.

Each row runs in its own child process (``--row-timeout``): optx.Dogleg and
IndirectLevenbergMarquardt hung in XLA:CPU on this machine in earlier runs, and a hang then cost
the whole table. Counting: a jflex step is one trial point evaluated with its Jacobian; "residual
evals" for scipy counts calls of the residual (trial points + 18 per FD Jacobian). Times: best of
``--repeat``; compilation excluded and printed.

    python benchmarks/bench_identify_flexible.py [--postures 20] [--freqs 120] [--repeat 3] [--tol 1e-10]
        [--noise 0.01] [--start-offset 0.5] [--rows optx-gn-armijo-normal/structured scipy-trf ...]
        [--row-timeout 900]

The issue-14 headline (RESULTS.md): ``--postures 20 --repeat 2 --start-offset 0.2 --rows
optx-gn-armijo-normal/structured optx-gn-armijo/structured scipy-trf`` (from +/-50 % the solvers
stop in different local minima, so no equal-cost comparison exists there).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx
import scipy.optimize

import jflex
from jflex import identify as idf

GEAR = 100.0
# planted values: reflected rotor inertias r^2 I_m of the order of the link inertias (2.3, 3.1, 0.85,
# 0.24, 0.25, 0.017 kg m^2 on the diagonal of M), so the rotors are neither negligible nor dominant
K_TRUE = np.array([2.0e4, 2.0e4, 1.0e4, 2.0e3, 2.0e3, 1.0e3])  # [N m/rad]
C_TRUE = np.array([10.0, 10.0, 5.0, 1.0, 1.0, 0.5])  # [N m s/rad]
I_TRUE = np.array([2e-4, 3e-4, 1e-4, 1e-5, 1e-5, 1e-6])  # [kg m^2], motor side
FRAME = "tool0"


def _model(robot, K, C, I):
    return jflex.Model(robot, [jflex.effects.FlexibleJoints(K, C, rotor_inertia=I, gear_ratio=[GEAR] * 6, coupling=False)])


def _postures(n, seed=1):
    rng = np.random.default_rng(seed)
    lo = np.array([-1.0, -2.0, 0.6, -2.2, 0.5, -1.0])
    hi = np.array([1.0, -0.6, 2.0, -0.6, 1.4, 1.0])
    return lo + (hi - lo) * rng.uniform(size=(n, 6))



def _timed(fn, u, reps=10):
    """``(fn(u), first-call seconds (compile + run), best of ``reps`` later calls)``: the best, not the
    mean, since the machine is shared."""
    t0 = time.perf_counter()
    out = np.asarray(fn(u))
    first = time.perf_counter() - t0
    ts = []
    for _ in range(reps):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(u))
        ts.append(time.perf_counter() - t0)
    return out, first, min(ts)


SOLVERS = {"jflex-lm": ("jflex LM (expand 0.75)", lambda tol: idf.levenberg_marquardt(rtol=tol, atol=tol)),
           "optx-lm": ("optimistix LM", lambda tol: optx.LevenbergMarquardt(rtol=tol, atol=tol)),
           "optx-gn": ("optimistix Gauss-Newton", lambda tol: optx.GaussNewton(rtol=tol, atol=tol)),
           # Gauss-Newton steps with a backtracking (Armijo) line search: the damped Gauss-Newton method
           "optx-gn-armijo": ("optimistix Gauss-Newton + Armijo backtracking",
                              lambda tol: eqx.tree_at(lambda s: s.search, optx.GaussNewton(rtol=tol, atol=tol),
                                                      optx.BacktrackingArmijo())),
           # the same, its Gauss-Newton step from the normal equations (Cholesky of J^T J, 18 x 18) instead
           # of lineax's default QR of the (m, 18) Jacobian
           "optx-gn-armijo-normal": ("optimistix Gauss-Newton + Armijo, normal equations",
                                     lambda tol: eqx.tree_at(lambda s: s.search, optx.GaussNewton(
                                         rtol=tol, atol=tol, linear_solver=lx.Normal(lx.Cholesky())),
                                         optx.BacktrackingArmijo())),
           "optx-indirect-lm": ("optimistix indirect LM", lambda tol: optx.IndirectLevenbergMarquardt(rtol=tol, atol=tol)),
           "optx-dogleg": ("optimistix Dogleg", lambda tol: optx.Dogleg(rtol=tol, atol=tol))}
JACS = {"fwd": "jax.jacfwd through jflex.frf's JVP", "bwd": "jax.jacrev", "structured": "structured exact JVP"}


def _setup(a):
    robot = jflex.load_robot("ur5")
    true = _model(robot, K_TRUE, C_TRUE, I_TRUE)
    post = _postures(a.postures)
    omega = 2 * np.pi * np.linspace(a.fmin, a.fmax, a.freqs)
    hold, comps = (), "full"
    H = jax.jit(jax.vmap(lambda q: jflex.frf(true, q, omega, hold=hold, frame=FRAME, components=comps)))(jnp.asarray(post))
    H = np.asarray(H)
    rng = np.random.default_rng(2)
    H = H * np.exp(a.noise * (rng.normal(size=H.shape) + 1j * rng.normal(size=H.shape)))
    data = idf.FRFData(post, omega, H, hold=hold, frame=FRAME, components=comps)
    spec = idf.ParameterSpec([idf.Free("K", lambda m: m.effects[0].stiffness, transform=idf.Log()),
                              idf.Free("C", lambda m: m.effects[0].damping, transform=idf.Log()),
                              idf.Free("I_m", lambda m: m.effects[0].rotor_inertia, transform=idf.Log())]).bind(true)
    sgn = np.array([1.0 + a.start_offset, 1.0 - a.start_offset] * 3)
    start = _model(robot, K_TRUE * sgn, C_TRUE * sgn[::-1], I_TRUE * sgn)
    u0 = jnp.asarray(spec.pack(start), dtype=jnp.float64)
    truth = np.log(np.concatenate([K_TRUE, C_TRUE, I_TRUE]))
    assert np.allclose(np.asarray(spec.pack(true)), truth)

    def resid(u, args=None):
        return idf.residual_vector(spec.apply(start, u), data)

    r_jit = jax.jit(resid)

    def cost(u):
        return 0.5 * float(np.sum(np.asarray(r_jit(jnp.asarray(u))) ** 2))

    return dict(robot=robot, true=true, post=post, omega=omega, data=data, spec=spec, start=start, u0=u0, truth=truth,
                sgn=sgn, resid=resid, r_jit=r_jit, cost=cost)


def _run_row(a, S, row):
    """One row of the table: ``scipy-<method>`` or ``<solver>/<jac>``; best of ``a.repeat``."""
    u0, truth, cost = S["u0"], S["truth"], S["cost"]
    n = u0.shape[0]
    if row.startswith("scipy-"):
        meth = row[len("scipy-"):]
        r_jit = S["r_jit"]
        t0 = time.perf_counter()
        jax.block_until_ready(r_jit(u0))
        comp = time.perf_counter() - t0
        calls = [0]

        def fun(u):
            calls[0] += 1
            return np.asarray(r_jit(jnp.asarray(u)))

        kw = dict(x_scale="jac") if meth != "lm" else dict(x_scale=1.0)
        runs = []
        for _ in range(a.repeat):
            calls[0] = 0
            t0 = time.perf_counter()
            ls = scipy.optimize.least_squares(fun, np.asarray(u0), method=meth, xtol=a.tol, ftol=a.tol, gtol=a.tol,
                                              max_nfev=100 * a.max_steps, **kw)
            runs.append((time.perf_counter() - t0, ls, calls[0]))
        t_s, ls, ev = min(runs, key=lambda x: x[0])
        njev = ls.njev if ls.njev is not None else (ev - ls.nfev) // n
        return dict(label=f"scipy least_squares {meth} ({'x_scale jac' if meth != 'lm' else 'x_scale 1'}), FD Jacobian",
                    t=t_s, comp=comp, steps=int(njev), trial=int(ls.nfev), evals=str(ev), cost=cost(ls.x),
                    err=float(np.abs(ls.x - truth).max()), u=np.asarray(ls.x).tolist(), stop=f"status {ls.status}")
    name, jac = row.split("/")
    label0, make = SOLVERS[name]
    solver = make(a.tol)
    if jac == "structured":
        fn = idf.sparse_frf_residual(S["spec"], S["start"], S["data"])
        fn2 = lambda u, args=None: fn(u)
        mode = "fwd"
    else:
        fn2, mode = S["resid"], jac
    solve = eqx.filter_jit(lambda u: (lambda s: (s.value, s.stats["num_steps"], s.result == optx.RESULTS.successful))(
        optx.least_squares(fn2, solver, u, options={"jac": mode}, max_steps=a.max_steps, throw=False)))
    t0 = time.perf_counter()
    sol = jax.block_until_ready(solve(u0))
    first = time.perf_counter() - t0
    times = []
    for _ in range(a.repeat):
        t0 = time.perf_counter()
        sol = jax.block_until_ready(solve(u0))
        times.append(time.perf_counter() - t0)
    u = np.asarray(sol[0])
    return dict(label=f"{label0}, {JACS[jac]}", t=min(times), comp=first - min(times), steps=int(sol[1]),
                evals=f"{int(sol[1])} r+J", cost=cost(u), err=float(np.abs(u - truth).max()), u=u.tolist(),
                stop="successful" if bool(sol[2]) else "max_steps/failed")


def _child(a, row):
    """Run ``row`` in a child process (a hang or a crash cannot lose the table); None on timeout."""
    with tempfile.TemporaryDirectory() as d:
        out = os.path.join(d, "row.json")
        cmd = [sys.executable, os.path.abspath(__file__), "--postures", str(a.postures), "--freqs", str(a.freqs),
               "--fmin", str(a.fmin), "--fmax", str(a.fmax), "--repeat", str(a.repeat), "--tol", str(a.tol),
               "--noise", str(a.noise), "--max-steps", str(a.max_steps), "--start-offset", str(a.start_offset),
               "--row", row, "--row-out", out]
        t0 = time.perf_counter()
        try:
            p = subprocess.run(cmd, timeout=a.row_timeout, capture_output=True, text=True)
        except subprocess.TimeoutExpired:
            print(f"[progress] {row}: no result after {a.row_timeout:.0f} s (killed)", flush=True)
            return dict(row=row, failed=f"timeout {a.row_timeout:.0f} s")
        if p.returncode != 0 or not os.path.exists(out):
            print(f"[progress] {row}: failed (rc {p.returncode}): {p.stderr[-2000:]}", flush=True)
            return dict(row=row, failed=f"rc {p.returncode}")
        with open(out) as f:
            r = json.load(f)
        print(f"[progress] {row}: best {r['t']:.3f} s, {r['steps']} steps, cost {r['cost']:.6e} "
              f"(child {time.perf_counter() - t0:.0f} s)", flush=True)
        return r


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--postures", type=int, default=20)
    ap.add_argument("--freqs", type=int, default=120)
    ap.add_argument("--fmin", type=float, default=5.0)
    ap.add_argument("--fmax", type=float, default=100.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--tol", type=float, default=1e-10, help="rtol = atol (optimistix) = xtol = ftol = gtol (scipy)")
    ap.add_argument("--noise", type=float, default=0.01, help="relative log-normal noise on the planted FRFs")
    ap.add_argument("--max-steps", type=int, default=200)
    ap.add_argument("--start-offset", type=float, default=0.5,
                    help="start = truth x (1 +/- offset), signs alternating (K and I_m +,-,...; C -,+,...)")
    ap.add_argument("--rows", nargs="+", default=["optx-gn-armijo-normal/structured", "optx-gn-armijo/structured",
                                                   "optx-gn/fwd", "jflex-lm/structured", "scipy-trf"],
                    help="table rows: scipy-lm | scipy-trf | scipy-dogbox (FD Jacobians) or SOLVER/JAC with SOLVER in "
                         f"{list(SOLVERS)} and JAC in {list(JACS)} (the first exact row is the reference of the cost "
                         "differences). optx-dogleg and optx-indirect-lm hung in XLA:CPU's Execute (all threads idle in "
                         "a futex wait, jax 0.10.2) on this machine in earlier runs: each row runs in its own child "
                         "process with --row-timeout, so a hang costs that row only")
    ap.add_argument("--row-timeout", type=float, default=900.0)
    ap.add_argument("--row", help=argparse.SUPPRESS)
    ap.add_argument("--row-out", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)

    S = _setup(a)
    if a.row:  # child: one row, written as JSON
        with open(a.row_out, "w") as f:
            json.dump(_run_row(a, S, a.row), f)
        return None

    true, post, omega, data, spec, start = S["true"], S["post"], S["omega"], S["data"], S["spec"], S["start"]
    u0, truth, resid, r_jit, cost = S["u0"], S["truth"], S["resid"], S["r_jit"], S["cost"]
    hold = ()
    fr = jax.jit(jax.vmap(lambda q: jflex.modal_analysis(true, q, hold=hold).frequency))(jnp.asarray(post))
    flex = np.sort(np.asarray(fr), axis=1)[:, 6:]  # every flexible mode in the band; the 6 others are the free
    rigid = np.sort(np.asarray(fr), axis=1)[:, :6]  # motor side's rigid-body/gravity modes

    # --- per-evaluation costs (jitted, steady state) and the structured JVP checked against jacfwd ---------
    r0, compile_res, t_res = _timed(r_jit, u0, 20)
    jac_fwd = jax.jit(jax.jacfwd(resid))
    J0, compile_jac, t_jac = _timed(jac_fwd, u0, 20)
    sres = idf.sparse_frf_residual(spec, start, data)
    jac_s = jax.jit(jax.jacfwd(sres))
    Js, compile_js, t_js = _timed(jac_s, u0, 20)
    rng = np.random.default_rng(5)
    u1 = u0 + jnp.asarray(rng.normal(scale=0.2, size=u0.shape))
    check = max(float(np.abs(Js - J0).max() / np.abs(J0).max()),
                float(np.abs(np.asarray(jac_s(u1)) - np.asarray(jac_fwd(u1))).max() / np.abs(np.asarray(jac_fwd(u1))).max()))
    assert check < 1e-9, f"structured Jacobian differs from jax.jacfwd: {check:.2e}"
    assert np.array_equal(np.asarray(jax.jit(sres)(u0)), r0)
    sv = np.linalg.svd(J0, compute_uv=False)
    print(f"[progress] residual {1e3 * t_res:.1f} ms, jacfwd {1e3 * t_jac:.1f} ms, structured {1e3 * t_js:.1f} ms "
          f"(max rel. diff {check:.1e})", flush=True)

    rows = [_child(a, r) for r in a.rows]
    c_true = cost(truth)

    # --- table ---------------------------------------------------------------------------------------
    done = [r for r in rows if "failed" not in r]
    exact = [r for r in done if not r["label"].startswith("scipy")]
    sc = [r for r in done if r["label"].startswith("scipy")]
    ref = exact[0] if exact else done[0]
    ref_u = np.asarray(ref["u"])
    nres = r0.shape[0]
    print(f"UR5 flexible-joint tool-FRF fit: {a.postures} postures x {a.freqs} frequencies ({a.fmin:g}-{a.fmax:g} Hz) x 6x6 "
          f"tool FRF ({FRAME}, components full, motor side free) -> {nres} residuals, 18 parameters (log K, log C, log I_m); "
          f"noise {a.noise:g}; tol {a.tol:g}; best of {a.repeat}")
    print(f"flexible modes of the truth over the postures: {flex.min():.1f}-{flex.max():.1f} Hz (band {a.fmin:g}-{a.fmax:g} Hz); "
          f"motor-side rigid/gravity modes <= {rigid.max():.2f} Hz")
    print(f"start: +/-{100 * a.start_offset:g} % (K x {S['sgn'].tolist()}, C x {S['sgn'][::-1].tolist()}, I_m x {S['sgn'].tolist()}); cost at start "
          f"{cost(u0):.6e}, at the truth {c_true:.6e}; Jacobian at the start: singular values {sv[0]:.2e} .. {sv[-1]:.2e} "
          f"(cond {sv[0] / sv[-1]:.1e})")
    hdr = (f"| {'solver, Jacobian':68s} | time [s] | compile [s] | iterations | residual evals | final cost | rel. cost diff vs 1st "
           f"| max abs(u - u_true) | max abs(u - u_1st) | stop |")
    print(hdr)
    print("|" + "|".join("-" * len(c) for c in hdr.split("|")[1:-1]) + "|")
    for r in rows:
        if "failed" in r:
            print(f"| {r['row']:68s} | no result: {r['failed']} |")
            continue
        its = f"{r['steps']}" if "trial" not in r else f"{r['steps']} ({r['trial']} trial)"
        print(f"| {r['label']:68s} | {r['t']:8.3f} | {r['comp']:11.1f} | {its:>10s} | {r['evals']:>14s} | {r['cost']:.6e} | "
              f"{(r['cost'] - ref['cost']) / ref['cost']:+.2e} | {r['err']:.3e} | {np.abs(np.asarray(r['u']) - ref_u).max():.2e} | "
              f"{r['stop']} |")
    n = u0.shape[0]
    print(f"per evaluation (jitted, best of 20): residual {1e3 * t_res:.2f} ms; Jacobian by jax.jacfwd (jflex.frf's JVP) "
          f"{1e3 * t_jac:.2f} ms ({t_jac / t_res:.1f}x the residual); structured exact Jacobian {1e3 * t_js:.2f} ms "
          f"({t_js / t_res:.1f}x; sparsity entries per parameter {list(sres.entries_per_parameter)}); an FD Jacobian is {n} residuals. "
          f"Compile: residual {compile_res:.1f} s, jacfwd {compile_jac:.1f} s, structured {compile_js:.1f} s")
    best_s = min(sc, key=lambda r: r["t"]) if sc else None
    if best_s is not None:
        for j in exact:
            d = (best_s["cost"] - j["cost"]) / j["cost"]
            print(f"headline: fastest scipy ({best_s['label'].split(',')[0]}) / {j['label']} = {best_s['t'] / j['t']:.2f}x; "
                  f"final cost rel. diff (scipy - jflex) / jflex {d:+.2e} ({'EQUAL' if abs(d) <= 1e-6 else 'NOT equal'} at 1e-6)")
    return dict(rows=rows)


if __name__ == "__main__":
    main()
