"""Benchmark: multi-posture tool-FRF fit of 18 joint parameters (K, C, rotor inertia of a 6-joint UR5).

jflex's exact-Jacobian least squares (``optx.least_squares`` with ``jflex.identify.levenberg_marquardt``,
optimistix's own ``LevenbergMarquardt``, ``GaussNewton`` and ``IndirectLevenbergMarquardt``; Jacobian
by forward-mode AD, the whole solve jitted, the postures vmapped inside ``FRFData``) against ``scipy.optimize.least_squares`` with finite-difference Jacobians calling the SAME
jitted residual, from the SAME start, with the same stopping tolerance, in one process. Not a
test: run it and read the table.

Set-up: ``jflex.load_robot("ur5")`` (6 revolute joints, gravity as loaded) with
``FlexibleJoints(K, C, rotor_inertia=I_m, gear_ratio=100, coupling=False)`` on every joint; the
tool FRF at ``tool0``, ``components="full"`` (6x6: forces and moments in, translations and
rotations out; the translational block alone does not see joint 6, whose axis passes through
tool0), at ``--postures`` random postures and ``--freqs`` frequencies in 5-100 Hz. The motor side
is left FREE (``hold=()``): with ``hold="actuated"`` (the motor angles clamped, as in
``bench_identify.py``) and ``coupling=False`` the rotor inertia does not enter the FRF at all, so
it could not be fitted. The planted FRFs carry ``--noise`` (default 1 %) log-normal multiplicative
noise on magnitude and phase, so the minimum has a non-zero cost and "equal final cost" means
something. Free: log K (6), log C (6), log I_m (6); start +/-50 % off the truth, alternating signs.

Counting: a jflex step is one trial point evaluated with its Jacobian (one forward-mode
linearisation, 18 tangents); "residual evals" for scipy counts calls of the residual (trial
points + 18 per FD Jacobian). Times: best of ``--repeat``; compilation excluded and printed.

    python benchmarks/bench_identify_flexible.py [--postures 20] [--freqs 120] [--repeat 3] [--tol 1e-10]
        [--noise 0.01] [--scipy-methods lm trf] [--jac fwd]
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



def _timed(fn, u, reps=3):
    """``(fn(u), first-call seconds (compile + run), seconds per later call)``."""
    t0 = time.perf_counter()
    out = np.asarray(fn(u))
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    for _ in range(reps):
        jax.block_until_ready(fn(u))
    return out, first, (time.perf_counter() - t0) / reps

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
    ap.add_argument("--jac", default="fwd", choices=["fwd", "bwd"], help="optimistix Jacobian mode (its option 'jac')")
    ap.add_argument("--scipy-methods", nargs="+", default=["lm", "trf"], choices=["lm", "trf", "dogbox"])
    ap.add_argument("--solvers", nargs="+", default=["jflex-lm", "optx-lm", "optx-gn"],
                    choices=["jflex-lm", "optx-lm", "optx-gn", "optx-indirect-lm"],
                    help="exact-Jacobian rows (the first is the reference of the cost differences); optx.Dogleg is left "
                         "out, and optx-indirect-lm is off by default: at 5 postures both hung in XLA:CPU's Execute (all threads "
                         "idle in a futex wait, jax 0.10.2) on this machine")
    a = ap.parse_args(argv)

    robot = jflex.load_robot("ur5")
    true = _model(robot, K_TRUE, C_TRUE, I_TRUE)
    post = _postures(a.postures)
    omega = 2 * np.pi * np.linspace(a.fmin, a.fmax, a.freqs)
    hold, comps = (), "full"

    # every flexible mode in the band (the 6 others are the free motor side's rigid-body/gravity modes)
    fr = jax.jit(jax.vmap(lambda q: jflex.modal_analysis(true, q, hold=hold).frequency))(jnp.asarray(post))
    flex = np.sort(np.asarray(fr), axis=1)[:, 6:]
    rigid = np.sort(np.asarray(fr), axis=1)[:, :6]

    H = jax.jit(jax.vmap(lambda q: jflex.frf(true, q, omega, hold=hold, frame=FRAME, components=comps)))(jnp.asarray(post))
    H = np.asarray(H)
    rng = np.random.default_rng(2)
    H = H * np.exp(a.noise * (rng.normal(size=H.shape) + 1j * rng.normal(size=H.shape)))
    data = idf.FRFData(post, omega, H, hold=hold, frame=FRAME, components=comps)
    spec = idf.ParameterSpec([idf.Free("K", lambda m: m.effects[0].stiffness, transform=idf.Log()),
                              idf.Free("C", lambda m: m.effects[0].damping, transform=idf.Log()),
                              idf.Free("I_m", lambda m: m.effects[0].rotor_inertia, transform=idf.Log())]).bind(true)
    sgn = np.array([1.5, 0.5] * 3)
    start = _model(robot, K_TRUE * sgn, C_TRUE * sgn[::-1], I_TRUE * sgn)
    u0 = jnp.asarray(spec.pack(start), dtype=jnp.float64)
    truth = np.log(np.concatenate([K_TRUE, C_TRUE, I_TRUE]))
    assert np.allclose(np.asarray(spec.pack(true)), truth)

    def resid(u, args=None):
        return idf.residual_vector(spec.apply(start, u), data)

    r_jit = jax.jit(resid)
    r0, compile_res, t_res = _timed(r_jit, u0)
    jac_fn = jax.jit(jax.jacfwd(resid) if a.jac == "fwd" else jax.jacrev(resid))
    J0, compile_jac, t_jac = _timed(jac_fn, u0)
    sv = np.linalg.svd(J0, compute_uv=False)

    def cost(u):
        return 0.5 * float(np.sum(np.asarray(r_jit(jnp.asarray(u))) ** 2))

    c_true = cost(truth)
    print(f"[progress] residual {1e3 * t_res:.1f} ms, Jacobian {1e3 * t_jac:.1f} ms", flush=True)

    # --- scipy: FD Jacobians on the same jitted residual ---------------------------------------------
    calls = [0]

    def fun(u):
        calls[0] += 1
        return np.asarray(r_jit(jnp.asarray(u)))

    srows = []
    n = u0.shape[0]
    for meth in a.scipy_methods:
        kw = dict(x_scale="jac") if meth != "lm" else dict(x_scale=1.0)
        runs = []
        for _ in range(a.repeat):
            calls[0] = 0
            t0 = time.perf_counter()
            ls = scipy.optimize.least_squares(fun, np.asarray(u0), method=meth, xtol=a.tol, ftol=a.tol, gtol=a.tol,
                                              max_nfev=100 * a.max_steps, **kw)
            runs.append((time.perf_counter() - t0, ls, calls[0]))
        t_s, ls, ev = min(runs, key=lambda x: x[0])
        print(f"[progress] scipy {meth}: best {t_s:.3f} s, {ls.nfev} trial points", flush=True)
        njev = ls.njev if ls.njev is not None else (ev - ls.nfev) // n
        srows.append(dict(label=f"scipy least_squares {meth} ({'x_scale jac' if meth != 'lm' else 'x_scale 1'}), FD Jacobian",
                          t=t_s, comp=compile_res, steps=njev, trial=ls.nfev, evals=str(ev), cost=cost(ls.x),
                          err=float(np.abs(ls.x - truth).max()), u=np.asarray(ls.x), stop=f"status {ls.status}"))

    # --- jflex: exact Jacobians, whole solve jitted -------------------------------------------------
    make = {"jflex-lm": ("jflex LM (expand 0.75), exact fwd-AD Jacobian", lambda: idf.levenberg_marquardt(rtol=a.tol, atol=a.tol)),
            "optx-lm": ("optimistix LM, exact fwd-AD Jacobian", lambda: optx.LevenbergMarquardt(rtol=a.tol, atol=a.tol)),
            "optx-gn": ("optimistix Gauss-Newton, exact fwd-AD Jacobian", lambda: optx.GaussNewton(rtol=a.tol, atol=a.tol)),
            "optx-indirect-lm": ("optimistix indirect LM, exact fwd-AD Jacobian",
                                 lambda: optx.IndirectLevenbergMarquardt(rtol=a.tol, atol=a.tol))}
    solvers = [(make[k][0], make[k][1]()) for k in a.solvers]
    if a.jac != "fwd":
        solvers = [(lab.replace("fwd-AD", f"{a.jac}-AD"), s) for lab, s in solvers]
    jrows = []
    for label, solver in solvers:
        solve = eqx.filter_jit(lambda u, solver=solver: (lambda s: (s.value, s.stats["num_steps"], s.result == optx.RESULTS.successful))(
            optx.least_squares(resid, solver, u, options={"jac": a.jac}, max_steps=a.max_steps, throw=False)))
        t0 = time.perf_counter()
        sol = jax.block_until_ready(solve(u0))
        first = time.perf_counter() - t0
        times = []
        for _ in range(a.repeat):
            t0 = time.perf_counter()
            sol = jax.block_until_ready(solve(u0))
            times.append(time.perf_counter() - t0)
        u = np.asarray(sol[0])
        print(f"[progress] {label}: best {min(times):.3f} s, {int(sol[1])} steps", flush=True)
        jrows.append(dict(label=label, t=min(times), comp=first - min(times), steps=int(sol[1]), evals=f"{int(sol[1])} r+J",
                          cost=cost(u), err=float(np.abs(u - truth).max()), u=u,
                          stop="successful" if bool(sol[2]) else "max_steps/failed"))

    # --- table ---------------------------------------------------------------------------------------
    ref = jrows[0]
    nres = r0.shape[0]
    print(f"UR5 flexible-joint tool-FRF fit: {a.postures} postures x {a.freqs} frequencies ({a.fmin:g}-{a.fmax:g} Hz) x 6x6 "
          f"tool FRF ({FRAME}, components full, motor side free) -> {nres} residuals, 18 parameters (log K, log C, log I_m); "
          f"noise {a.noise:g}; tol {a.tol:g}; best of {a.repeat}")
    print(f"flexible modes of the truth over the postures: {flex.min():.1f}-{flex.max():.1f} Hz (band {a.fmin:g}-{a.fmax:g} Hz; "
          f"per joint-mode min/max: " + ", ".join(f"{lo:.1f}/{hi:.1f}" for lo, hi in zip(flex.min(0), flex.max(0)))
          + f"); motor-side rigid/gravity modes <= {rigid.max():.2f} Hz")
    print(f"start: +/-50 % (K x {sgn.tolist()}, C x {sgn[::-1].tolist()}, I_m x {sgn.tolist()}); cost at start {cost(u0):.6e}, "
          f"at the truth {c_true:.6e}; Jacobian at the start: singular values {sv[0]:.2e} .. {sv[-1]:.2e} (cond {sv[0] / sv[-1]:.1e})")
    hdr = (f"| {'solver':52s} | time [s] | compile [s] | iterations | residual evals | final cost | rel. cost diff vs 1st row"
           f"| max abs(u - u_true) | max abs(u - u_jflex) | stop |")
    print(hdr)
    print("|" + "|".join("-" * len(c) for c in hdr.split("|")[1:-1]) + "|")
    for r in jrows + srows:
        its = f"{r['steps']}" if "trial" not in r else f"{r['steps']} ({r['trial']} trial)"
        print(f"| {r['label']:52s} | {r['t']:8.3f} | {r['comp']:11.1f} | {its:>10s} | {r['evals']:>14s} | {r['cost']:.6e} | "
              f"{(r['cost'] - ref['cost']) / ref['cost']:+.2e} | {r['err']:.3e} | {np.abs(r['u'] - ref['u']).max():.2e} | {r['stop']} |")
    for s in srows:
        for j in jrows:
            print(f"ratio {s['label']} / {j['label']}: time {s['t'] / j['t']:.2f}x")
    best_s = min(srows, key=lambda r: r["t"]) if srows else None
    if best_s is not None:
        for j in jrows:
            d = (best_s['cost'] - j['cost']) / j['cost']
            print(f"headline: fastest scipy ({best_s['label'].split(',')[0]}) / {j['label'].split(',')[0]} = "
                  f"{best_s['t'] / j['t']:.2f}x; equal final cost: rel. diff (scipy - jflex) / jflex {d:+.2e} "
                  f"({'EQUAL' if abs(d) <= 1e-6 else 'NOT equal'} at 1e-6)")
    print(f"per evaluation (jitted, steady state): residual {1e3 * t_res:.1f} ms, {a.jac}-mode Jacobian (jax.jac{a.jac}) "
          f"{1e3 * t_jac:.1f} ms ({t_jac / t_res:.1f}x the residual; an FD Jacobian is {n} residuals); compile: residual "
          f"{compile_res:.1f} s, Jacobian {compile_jac:.1f} s")
    return dict(jflex=ref["t"], scipy={r["label"]: r["t"] for r in srows})


if __name__ == "__main__":
    main()
