"""Benchmark: closed-loop output-error fit (CLOE) of a 6-DoF arm's base inertial + friction parameters.

Issue 14 item 3(a). A UR5 (``jflex.load_robot("ur5")``) with rotor armature and viscous + smooth
Coulomb friction (``tanh(qd / eps)``) tracks an exciting Fourier reference under a PD controller
with a feed-forward computed from the NOMINAL (CAD) model; the joint angles are recorded with
noise. The free vector is the BASE parameter vector psi (``jflex.identify.base_parameters`` of the
regressor with friction and armature: 36 rigid + 6 viscous + 6 Coulomb + 4 armature = 52 for the
UR5; identifying the 78 standard parameters is singular). A standard vector is rebuilt from psi
as ``theta = theta_cad + K^+ (psi - K theta_cad)`` (any theta with ``K theta = psi`` has the same
dynamics). Every residual is a closed-loop simulation through ``jflex.simulate`` from the known
initial state (single shooting; the loop keeps the simulation near the record).

Both fitters minimise the SAME residual (``ClosedLoopData.residuals``: the plain closed-loop
``jflex.simulate``; joint angles scaled per joint as ``jflex.identify.TimeData`` does), from the
SAME start (psi of the CAD model and catalogue friction), with the same stopping tolerance:

- jflex: ``jflex.identify.fit`` with ``optx.GaussNewton`` (``--solvers gn``, default; ``lm``:
  ``jflex.identify.levenberg_marquardt``, which took 29-30 steps here against 6) and the residual's exact
  Jacobian from FORWARD SENSITIVITY EQUATIONS integrated alongside the motion in one
  ``jflex.simulate`` call (the sensitivities are internal states ``z`` of the same effect):
  ``M S'' + (dtau/dq + Kp) S + (dtau/dqd + Kd) S' = -Y(q, qd, qdd) K^+``: the state terms as one
  ``jax.jvp`` of ``jflex.rnea`` (+ friction - control) per column of S, batched, and the parameter
  terms from the identification regressor (``jflex.identify.Regressor``), since the dynamics are
  linear in the parameters (``jflex.rnea_derivatives`` in their place was slower in the solve's loop). The residual
  carries it as a ``jax.custom_jvp``, so ``fit``'s ``jax.jacfwd`` gets it in one solve.
- scipy: ``scipy.optimize.least_squares`` (``--scipy-methods``: MINPACK ``lm`` and/or ``trf``) with
  finite-difference Jacobians calling the same jitted residual; one row per ``--diff-step``
  (scipy's default relative step ~1.5e-8 sees the adaptive solve's noise at rtol 1e-8; ``1e-4``
  is about sqrt(rtol)).

A second jflex row (``--jac-rtol 1e-6``) takes the Jacobian from a separate, looser sensitivity solve
(rtol 1e-6) and the residual from the plain solve at the fit's rtol: the Jacobian is then exact to
1e-6 rather than 1e-8 (the LM steps only need a good linear model; the residual stays exact).

Multiple shooting (``--segments S``): the record is cut into S pieces simulated side by side
(vmapped), each from its measured start state (angles with ``--noise``, velocities with
``--vel-noise``); the start states are data, not parameters. It did not make the solves cheaper
on this 2-core machine (5 s record: 130-270 ms per residual for S = 10-50 against 150 ms for S = 1,
Jacobian/residual ratio unchanged at ~14x), so the default is single shooting.

``--ad-jacobian`` also times one Jacobian by plain forward-mode AD through ``jflex.simulate``
(``jax.jacfwd``, 52 tangents, what ``fit`` does with ``jflex.identify.TimeData``): at 5 s / 500
samples it took 44-53 s against 0.15 s for the residual (and ~100 s to compile), far slower than an
FD Jacobian, so it is not a fit row.

Counting: a jflex step is one trial point evaluated with its Jacobian (one sensitivity solve);
"residual evals" for scipy counts calls of the residual (trial points + 52 per FD Jacobian).
Times: best of ``--repeat``; compilation excluded and printed separately. Final costs are
recomputed with the same jitted residual for every row.

    python benchmarks/bench_identify_output_error.py [--seconds 5] [--samples 500] [--max-iter 40] [--solvers gn lm]
        [--repeat 1] [--tol 1e-8] [--jac-rtol same 1e-6] [--diff-step 1e-4] [--scipy-methods lm] [--segments 1]
        [--ad-jacobian] [--quick]

``--quick`` (1 s record, 100 samples, 8 steps) is a smoke run: it does not converge, and its run
time is compilation (the sensitivity solve compiles in 50-90 s on this machine: about 6 min under load 5).
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import scipy.optimize

import jflex
from jflex import identify as idf
from jflex.effects import AbstractEffect

EPS = 0.05  # [rad/s] width of the smooth Coulomb sign (tanh)
FV_NOM = np.array([6.0, 6.0, 4.0, 1.5, 1.5, 1.0])  # catalogue-like viscous friction [N m s/rad]
FC_NOM = np.array([8.0, 8.0, 5.0, 2.0, 2.0, 1.5])  # Coulomb [N m]
IA_NOM = np.array([0.6, 0.6, 0.3, 0.05, 0.05, 0.05])  # reflected rotor inertia [kg m^2]
Q_MID = np.array([0.0, -1.2, 1.2, -1.5, -1.57, 0.0])  # centre of the reference [rad]


class ClosedLoopArm(AbstractEffect):
    """The arm's parameters (from the base vector ``psi``) and its PD + nominal feed-forward loop.

    ``theta = c + P psi`` is the standard vector ``[pi (10 n), Fv (n), Fc (n), Ia (n)]``; the
    effect sets the links' inertial parameters (``modify_robot``), adds the armature's kinetic
    energy and the friction and controller torques. With ``sensitivity`` on, its internal states
    are ``[vec S, vec S']`` (S = dq/dpsi, n x p) and ``state_rate`` gives their equations.
    """

    psi: jnp.ndarray
    c: jnp.ndarray
    traj: idf.FourierTrajectory
    kp: jnp.ndarray
    kd: jnp.ndarray
    nominal: jflex.Robot  # CAD robot of the feed-forward
    theta_nominal: jnp.ndarray
    columns: tuple = eqx.field(static=True)  # the independent standard parameters: theta[columns] carries psi
    eps: float = eqx.field(static=True)
    sensitivity: bool = eqx.field(static=True, default=False)

    def theta(self):
        return self.c.at[jnp.array(self.columns)].add(self.psi)

    def _split(self, n):
        th = self.theta()
        return th[: 10 * n], th[10 * n : 11 * n], th[11 * n : 12 * n], th[12 * n : 13 * n]

    def modify_robot(self, robot):
        return robot.replace(inertia=self._split(robot.nq)[0].reshape(robot.nq, 10))

    def kinetic_energy(self, robot, slots, x, xd):
        return 0.5 * jnp.sum(self._split(robot.nq)[3] * xd[: robot.nq] ** 2)

    def control(self, robot, t, q, qd):
        """PD on the reference + the nominal model's inverse dynamics along it [N m]."""
        n = robot.nq
        qr, qdr, qddr = self.traj(t)
        th = self.theta_nominal
        ff = (jflex.rnea(self.nominal, qr, qdr, qddr) + th[12 * n :] * qddr + th[10 * n : 11 * n] * qdr
              + th[11 * n : 12 * n] * jnp.tanh(qdr / self.eps))
        return self.kp * (qr - q) + self.kd * (qdr - qd) + ff

    def generalized_force(self, robot, slots, t, x, xd, z):
        n = robot.nq
        _, fv, fc, _ = self._split(n)
        q, qd = x[:n], xd[:n]
        f = self.control(robot, t, q, qd) - (fv * qd + fc * jnp.tanh(qd / self.eps))
        return jnp.zeros(slots.nx).at[:n].set(f)

    def state_names(self, robot):
        if not self.sensitivity:
            return ()
        n, p = robot.nq, len(self.columns)
        return tuple(f"S{k}[{i},{j}]" for k in ("", "d") for i in range(n) for j in range(p))

    def state_rate(self, robot, slots, t, x, xd, z):
        if not self.sensitivity:
            return jnp.zeros(0)
        n, p = robot.nq, len(self.columns)
        q, qd = x[:n], xd[:n]
        S, Sd = z[: n * p].reshape(n, p), z[n * p :].reshape(n, p)
        _, fv, fc, ia = self._split(n)
        # the motion's acceleration (the same equations the model integrates)
        zero = jnp.zeros_like(q)
        M = jflex.crba(robot, q) + jnp.diag(ia)
        h = jflex.rnea(robot, q, qd, zero) + fv * qd + fc * jnp.tanh(qd / self.eps)
        L = jnp.linalg.cholesky(M)
        qdd = jax.scipy.linalg.cho_solve((L, True), self.control(robot, t, q, qd) - h)
        # d(inverse dynamics + friction - control)/d(q, qd) . (S, S') at this motion: one jvp per
        # column, batched; the parameters enter linearly, through the regressor
        def g(q_, qd_):
            return (jflex.rnea(robot, q_, qd_, qdd) + fv * qd_ + fc * jnp.tanh(qd_ / self.eps)
                    - self.control(robot, t, q_, qd_))

        GS = jax.vmap(lambda s_, sd_: jax.jvp(g, (q, qd), (s_, sd_))[1], in_axes=1, out_axes=1)(S, Sd)
        Y = _REGRESSOR(robot, q, qd, qdd)[:, self.columns]  # d(torque)/d(psi) (n, p): P selects these columns
        Sdd = -jax.scipy.linalg.cho_solve((L, True), Y + GS)
        return jnp.concatenate([Sd.ravel(), Sdd.ravel()])


_REGRESSOR = idf.Regressor(viscous=True, coulomb=True, armature=True, coulomb_width=EPS)


class ClosedLoopData(idf.AbstractData):
    """Joint angles of a closed-loop run, compared with ``jflex.simulate`` of the model (whose first
    effect is a :class:`ClosedLoopArm`).

    The record is cut into ``segments`` equal pieces, simulated side by side (``jax.vmap``), each
    from its own start state ``(x0s[k], xd0s[k])``: the known initial state for the first, the
    measured state for the others (multiple shooting from measured states; the start states are
    data, not parameters). One segment is plain single-shooting output error. Residuals as
    :class:`jflex.identify.TimeData`'s (``(q_sim - q) / (std(q) sqrt(N))`` per joint) on every
    sample but the segments' first (a start state); their derivative with respect to the arm's
    ``psi`` comes from the sensitivity solve (a ``jax.custom_jvp``)."""

    ts: jnp.ndarray
    q: jnp.ndarray
    x0s: jnp.ndarray
    xd0s: jnp.ndarray
    simulate_kw: tuple = eqx.field(static=True)
    jacobian_kw: tuple = eqx.field(static=True, default=())  # overrides of simulate_kw for the sensitivity solve
    segments: int = eqx.field(static=True, default=1)
    name: str = eqx.field(static=True, default="q")

    def _scale(self):
        return jnp.maximum(jnp.std(self.q, axis=0), 1e-300) * jnp.sqrt(self.q.shape[0])

    def _measured(self):
        S = self.segments
        return self.q.reshape(S, -1, self.q.shape[1])[:, 1:]

    def simulate(self, model, outputs=("q",), kw=()):
        """Outputs per segment, each (S, L, ...), the segments' first samples left out."""
        S = self.segments
        kw = {**dict(self.simulate_kw), **dict(kw)}

        def one(tt, x0, xd0):
            return jflex.simulate(model, tt, x0, xd0, outputs=outputs, throw=False, **kw).outputs

        out = jax.vmap(one)(self.ts.reshape(S, -1), self.x0s, self.xd0s)
        return {k: v[:, 1:] for k, v in out.items()}

    def _flat(self, model):
        arm = model.effects[0]
        plain = eqx.tree_at(lambda m: m.effects[0].psi, model, jnp.zeros_like(arm.psi))

        @jax.custom_jvp
        def r_of(psi):
            m = eqx.tree_at(lambda mm: mm.effects[0].psi, plain, psi)
            return ((self.simulate(m)["q"] - self._measured()) / self._scale()).ravel()

        @r_of.defjvp
        def r_jvp(primals, tangents):
            (psi,), (dpsi,) = primals, tangents
            r, J = self.residual_and_jacobian(eqx.tree_at(lambda mm: mm.effects[0].psi, plain, psi))
            if self.jacobian_kw:  # a looser sensitivity solve: the residual from the plain one
                r = r_of(psi)
            return r, J @ dpsi

        return r_of(arm.psi)

    def residual_and_jacobian(self, model):
        """``(r (m,), dr/dpsi (m, p))`` from one solve with the sensitivity states."""
        arm = model.effects[0]
        m = eqx.tree_at(lambda mm: mm.effects[0], model, dataclasses.replace(arm, sensitivity=True))
        out = self.simulate(m, outputs=("q", "z"), kw=self.jacobian_kw)
        n = self.q.shape[1]
        p = arm.psi.shape[0]
        sc = self._scale()
        r = ((out["q"] - self._measured()) / sc).ravel()
        J = (out["z"][..., : n * p].reshape(-1, n, p) / sc[None, :, None]).reshape(-1, p)
        return r, J

    def residuals(self, model):
        return {f"time:{self.name}": self._flat(model)}

    def nrmse(self, model):
        e = (self.simulate(model)["q"] - self._measured()).reshape(-1, self.q.shape[1])
        return {f"time:{self.name}": jnp.mean(jnp.sqrt(jnp.mean(e**2, axis=0)) / jnp.std(self.q, axis=0))}


def build(a):
    """Robot, base-parameter map, planted and start models, the noisy record."""
    robot = jflex.load_robot("ur5")
    n = robot.nq
    t0 = time.perf_counter()
    bp = idf.base_parameters(robot, _REGRESSOR)
    K = np.asarray(bp.matrix())
    cols = tuple(bp.independent)
    P = np.zeros((K.shape[1], K.shape[0]))
    P[cols, np.arange(len(cols))] = 1.0  # K P = I: psi replaces the independent parameters
    t_base = time.perf_counter() - t0
    rng = np.random.default_rng(a.seed)
    th_cad = np.asarray(_REGRESSOR.vector(robot, fv=FV_NOM, fc=FC_NOM, armature=IA_NOM))
    # planted: +-5 % (1 sigma) on every non-zero inertial parameter, small offsets on the first
    # moments and products of inertia the CAD has at zero, friction and armature +-20 %
    th_true = th_cad * (1 + 0.05 * rng.standard_normal(th_cad.size))
    pi = th_true[: 10 * n].reshape(n, 10)
    pi[:, 1:4] += 0.01 * rng.standard_normal((n, 3))
    pi[:, [5, 7, 8]] += 0.002 * rng.standard_normal((n, 3))
    th_true[: 10 * n] = pi.ravel()
    th_true[10 * n :] = th_cad[10 * n :] * (1 + 0.2 * rng.standard_normal(3 * n))
    c = th_cad - P @ (K @ th_cad)
    psi_cad, psi_true = K @ th_cad, K @ th_true
    # exciting reference: a random 5-harmonic Fourier series at 0.2 Hz (not optimised), wrists faster
    amp = (0.12 * np.array([1, 1, 1, 2, 2, 2.5]))[:, None] * np.ones((1, 5))
    traj = idf.FourierTrajectory(jnp.asarray(rng.normal(size=(n, 5)) * amp), jnp.asarray(rng.normal(size=(n, 5)) * amp),
                                 jnp.asarray(Q_MID), jnp.asarray(2 * np.pi * 0.2))
    q0, qd0, _ = traj(0.0)
    # PD gains: closed-loop bandwidth --bandwidth Hz, damping 0.7, on the nominal diagonal inertia at q0
    m_diag = np.asarray(jflex.crba(robot, q0)).diagonal() + IA_NOM
    wc = 2 * np.pi * a.bandwidth
    kp, kd = m_diag * wc**2, 2 * 0.7 * m_diag * wc

    def model_of(psi):
        arm = ClosedLoopArm(jnp.asarray(psi, dtype=jnp.float64), jnp.asarray(c), traj, jnp.asarray(kp),
                            jnp.asarray(kd), robot, jnp.asarray(th_cad), cols, EPS)
        return jflex.Model(robot, [arm])

    ts = np.arange(a.samples) * (a.seconds / a.samples)
    kw = dict(rtol=a.rtol, atol=a.atol, max_steps=a.max_ode_steps)
    truth = model_of(psi_true)
    t0 = time.perf_counter()
    sim = jflex.simulate(truth, ts, q0, qd0, outputs=("q", "qd"), rtol=1e-11, atol=1e-13, max_steps=a.max_ode_steps)
    t_record = time.perf_counter() - t0
    q_clean, qd_clean = np.asarray(sim["q"]), np.asarray(sim["qd"])
    qm = q_clean + a.noise * rng.standard_normal(q_clean.shape)
    # segment starts: the known initial state, then measured angles and velocities (velocity noise
    # --vel-noise, as from a filtered derivative of the encoders)
    S = a.segments
    if a.samples % S:
        raise SystemExit(f"--samples {a.samples} does not split into --segments {S}")
    first = np.arange(S) * (a.samples // S)
    x0s = qm[first].copy()
    xd0s = qd_clean[first] + a.vel_noise * rng.standard_normal((S, n))
    x0s[0], xd0s[0] = np.asarray(q0), np.asarray(qd0)
    data = ClosedLoopData(jnp.asarray(ts), jnp.asarray(qm), jnp.asarray(x0s), jnp.asarray(xd0s), tuple(sorted(kw.items())), segments=S)
    qr = np.asarray(jax.vmap(traj)(jnp.asarray(ts))[0])
    info = dict(robot=robot, bp=bp, n=n, p=bp.rank, t_base=t_base, t_record=t_record, kp=kp, kd=kd,
                track=np.abs(q_clean - qr).max(0), qd_max=np.abs(np.asarray(sim["qd"])).max(0), q_range=np.ptp(q_clean, 0))
    return model_of, psi_cad, psi_true, data, info


def _timed(fn, u, reps=3):
    """``(fn(u), first-call seconds (compile + run), seconds per later call)``."""
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(u))
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    for _ in range(reps):
        jax.block_until_ready(fn(u))
    return out, first, (time.perf_counter() - t0) / reps


def _jflex_fit(model, spec, data, solver, max_iter):
    """One jflex fit: (result, run s excluding compile, compile s, mean s per r+J evaluation)."""
    stamps = []
    t0 = time.perf_counter()
    res = idf.fit(model, spec, data, solver, max_steps=max_iter, progress=False,
                  callback=lambda k, c, v: stamps.append(time.perf_counter()))
    tm = res.timing
    later = tm["jacobian_evals"] - 1
    mean_eval = tm["jacobian_run_s"] / later if later > 0 else float("nan")
    # the first stamp comes after: compile + the start evaluation + the first step's evaluation and LM compile
    run = (stamps[-1] - stamps[0]) + 2 * mean_eval if stamps else float("nan")
    comp = (stamps[0] - t0) - 2 * mean_eval if stamps else float("nan")
    return res, run, comp, mean_eval


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=5.0, help="record length [s]")
    ap.add_argument("--samples", type=int, default=500, help="samples of the record (6 joint angles each)")
    ap.add_argument("--max-iter", type=int, default=40, help="jflex LM steps; scipy max_nfev = this x 3 trial points")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--tol", type=float, default=1e-8, help="jflex LM rtol = atol; scipy xtol = ftol = gtol")
    ap.add_argument("--rtol", type=float, default=1e-8, help="ODE rtol of the fit's solves")
    ap.add_argument("--atol", type=float, default=1e-10, help="ODE atol of the fit's solves")
    ap.add_argument("--max-ode-steps", type=int, default=100_000)
    ap.add_argument("--noise", type=float, default=2e-5, help="joint-angle noise std [rad] (encoder-like)")
    ap.add_argument("--bandwidth", type=float, default=3.0, help="PD closed-loop bandwidth [Hz]")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--segments", type=int, default=1, help="shooting segments (1: single shooting); they run vmapped")
    ap.add_argument("--vel-noise", type=float, default=1e-3, help="noise std of the measured start velocities [rad/s]")
    ap.add_argument("--diff-step", nargs="+", default=["1e-4"],
                    help="scipy's relative FD steps, one row each ('default': scipy's own, ~1.5e-8)")
    ap.add_argument("--jac-rtol", nargs="+", default=["same", "1e-6"],
                    help="jflex rows: 'same' (residual and Jacobian from one sensitivity solve at --rtol) or an rtol for a "
                         "separate, looser sensitivity solve (the residual then from the plain solve at --rtol)")
    ap.add_argument("--solvers", nargs="+", default=["gn"], choices=["gn", "lm"],
                    help="jflex solvers: optimistix Gauss-Newton, jflex.identify.levenberg_marquardt")
    ap.add_argument("--scipy-methods", nargs="+", default=["lm"], choices=["lm", "trf"])
    ap.add_argument("--ad-jacobian", action="store_true", help="also time one plain forward-mode AD Jacobian (slow)")
    ap.add_argument("--quick", action="store_true", help="smoke run: 1 s record, 100 samples, 8 steps")
    a = ap.parse_args(argv)
    if a.quick:
        a.seconds, a.samples, a.max_iter, a.repeat = 1.0, 100, 8, 1

    model_of, psi_cad, psi_true, data, info = build(a)
    n, p = info["n"], info["p"]
    start = model_of(psi_cad)
    scale = np.maximum(np.abs(psi_cad), 1e-2)  # u = psi / scale: entries of order one
    spec = idf.ParameterSpec([idf.Free("psi", lambda m: m.effects[0].psi, transform=idf.Identity(scale))]).bind(start)
    u0 = np.asarray(spec.pack(start), dtype=float)
    u_true = psi_true / scale
    print(f"[progress] base parameters {p} of {len(info['bp'].names)} ({info['t_base']:.1f} s); record {info['t_record']:.1f} s",
          flush=True)

    @jax.jit
    def r_jit(u):
        return idf.residual_vector(spec.apply(start, u), data)

    @jax.jit
    def rj_sens(u):
        return data.residual_and_jacobian(spec.apply(start, u))

    def cost(u):
        return 0.5 * float(jnp.sum(r_jit(jnp.asarray(u)) ** 2))

    r0, comp_r, t_r = _timed(r_jit, jnp.asarray(u0))
    (_, J0), comp_rj, t_rj = _timed(rj_sens, jnp.asarray(u0))
    J0 = np.asarray(J0) * scale[None, :]  # d r / d u
    sv = np.linalg.svd(J0, compute_uv=False)
    print(f"[progress] residual {1e3 * t_r:.1f} ms (compile {comp_r:.1f} s), residual + sensitivity Jacobian "
          f"{1e3 * t_rj:.1f} ms (compile {comp_rj:.1f} s)", flush=True)
    # check the sensitivity Jacobian against central differences of the residual on a few columns
    cols = [0, p // 2, p - 1]
    h = 1e-4
    fd = np.stack([(np.asarray(r_jit(jnp.asarray(u0 + h * e))) - np.asarray(r_jit(jnp.asarray(u0 - h * e)))) / (2 * h)
                   for e in np.eye(p)[cols]], axis=1)
    jac_err = np.abs(fd - J0[:, cols]).max() / np.abs(J0[:, cols]).max()
    ad = None
    if a.ad_jacobian:
        jf = jax.jit(jax.jacfwd(r_jit))
        Jad, comp_ad, t_ad = _timed(jf, jnp.asarray(u0), reps=1)
        ad = (comp_ad - t_ad, t_ad, float(np.abs(np.asarray(Jad) - J0).max() / np.abs(J0).max()))
        print(f"[progress] plain forward-mode AD Jacobian {t_ad:.2f} s (compile {ad[0]:.1f} s)", flush=True)

    # --- jflex: LM, exact sensitivity Jacobians ------------------------------------------------------
    solvers = {"lm": ("LM", lambda: idf.levenberg_marquardt(a.tol, a.tol)),
               "gn": ("Gauss-Newton", lambda: optx.GaussNewton(rtol=a.tol, atol=a.tol))}
    jrows = []
    for sk, jr in [(sk, jr) for sk in a.solvers for jr in a.jac_rtol]:
        sname, make = solvers[sk]
        solver = make()
        same = jr.lower() == "same"
        dj = data if same else dataclasses.replace(data, jacobian_kw=(("atol", float(jr) * a.atol / a.rtol), ("rtol", float(jr))))
        runs = [_jflex_fit(start, spec, dj, solver, a.max_iter) for _ in range(a.repeat)]
        res, t_j, comp_j, eval_j = min(runs, key=lambda x: x[1])
        label = (f"jflex {sname}, sensitivity Jacobian (same solve)" if same else
                 f"jflex {sname}, sensitivity Jacobian at rtol {float(jr):g} + residual solve")
        jrows.append(dict(label=label, t=t_j, comp=comp_j, eval=eval_j, res=res, u=np.asarray(res.u), cost=cost(res.u)))
        print(f"[progress] {label}: {t_j:.2f} s, {res.steps} steps, {res.result}, {1e3 * eval_j:.0f} ms per r+J", flush=True)

    # --- scipy: FD Jacobians on the same jitted residual ----------------------------------------------
    calls = [0]

    def fun(u):
        calls[0] += 1
        return np.asarray(r_jit(jnp.asarray(u)))

    srows = []
    for meth in a.scipy_methods:
        for ds in a.diff_step:
            step = None if ds.lower() == "default" else float(ds)
            best = None
            for _ in range(a.repeat):
                calls[0] = 0
                t0 = time.perf_counter()
                ls = scipy.optimize.least_squares(fun, u0, method=meth, xtol=a.tol, ftol=a.tol, gtol=a.tol,
                                                  max_nfev=3 * a.max_iter, diff_step=step)
                run = (time.perf_counter() - t0, ls, calls[0])
                best = run if best is None or run[0] < best[0] else best
            t_s, ls, ev = best
            njev = ls.njev if ls.njev is not None else (ev - ls.nfev) // p
            srows.append(dict(label=f"scipy {meth}, FD Jacobian, diff_step {ds}", t=t_s, steps=njev, trial=ls.nfev, evals=ev,
                              cost=cost(ls.x), u=np.asarray(ls.x), stop=f"status {ls.status}"))
            print(f"[progress] {srows[-1]['label']}: {t_s:.2f} s, {ls.nfev} trial points, {ev} residual calls", flush=True)

    # --- table ------------------------------------------------------------------------------------------
    ref = jrows[0]
    cj = ref["cost"]
    c0, ct = cost(u0), cost(u_true)
    print(f"\nUR5 closed-loop output-error fit: {a.seconds:g} s record, {a.samples} samples x {n} joint angles, {a.segments} "
          f"segment(s) ({r0.shape[0]} residuals), {p} base parameters (36 rigid + 6 Fv + 6 Fc + 4 armature; of "
          f"{len(info['bp'].names)} standard); noise {a.noise:g} rad; PD bandwidth {a.bandwidth:g} Hz + nominal feed-forward; "
          f"tracking error of the truth max {info['track'].max():.2e} rad, |qd| max {info['qd_max'].max():.2f} rad/s; fit "
          f"solves Tsit5 rtol {a.rtol:g} atol {a.atol:g}; tol {a.tol:g}; best of {a.repeat}")
    print(f"start (CAD + catalogue friction) cost {c0:.6e}, planted parameters' cost {ct:.6e}; d r/d u at the start: "
          f"singular values {sv[0]:.2e} .. {sv[-1]:.2e} (cond {sv[0] / sv[-1]:.1e}); sensitivity Jacobian vs central "
          f"differences (3 columns): max rel. diff {jac_err:.1e}")
    hdr = ("| solver | time [s] | compile [s] | iterations (trial points) | residual evals | final cost | rel. cost diff vs 1st row "
           "| max abs(u - u_true) | stop |")
    print(hdr)
    print("|" + "|".join("---" for _ in hdr.split("|")[1:-1]) + "|")
    for r in jrows:
        st = r["res"].steps
        print(f"| {r['label']} | {r['t']:.2f} | {r['comp']:.1f} | {st} ({st}) | {st + 1} r+J | {r['cost']:.6e} "
              f"| {(r['cost'] - cj) / cj:+.2e} | {np.abs(r['u'] - u_true).max():.3e} | {r['res'].result} |")
    for r in srows:
        print(f"| {r['label']} | {r['t']:.2f} | {comp_r:.1f} | {r['steps']} ({r['trial']}) | {r['evals']} | {r['cost']:.6e} "
              f"| {(r['cost'] - cj) / cj:+.2e} | {np.abs(r['u'] - u_true).max():.3e} | {r['stop']} |")
    for r in srows:
        for j in jrows:
            d = (r["cost"] - j["cost"]) / j["cost"]
            print(f"ratio {r['label']} / {j['label']}: time {r['t'] / j['t']:.2f}x; final cost rel. diff (scipy - jflex) / jflex "
                  f"{d:+.2e} ({'EQUAL' if abs(d) <= 1e-6 else 'NOT equal'} at 1e-6)")
    print(f"per evaluation (jitted, steady state): residual {1e3 * t_r:.1f} ms; residual + sensitivity Jacobian (same solve) "
          f"{1e3 * t_rj:.1f} ms ({t_rj / t_r:.1f}x the residual; an FD Jacobian is {p} residuals, {p}x); in the fits: "
          + ", ".join(f"{1e3 * j['eval']:.0f} ms per r+J ({j['eval'] / t_r:.1f}x)" for j in jrows)
          + f"; compile: residual {comp_r:.1f} s, sensitivity solve {comp_rj:.1f} s, jflex fits "
          + ", ".join(f"{j['comp']:.1f} s" for j in jrows))
    for j in jrows:
        h = np.asarray(j["res"].history)
        print(f"{j['label']}: cost per step " + " ".join(f"{c:.6g}" for c in h)
              + f"; first within 1e-6 of its final cost at step {int(np.argmax(h <= j['cost'] * (1 + 1e-6)))}")
    if ad is not None:
        print(f"plain forward-mode AD Jacobian through jflex.simulate (jax.jacfwd, {p} tangents): {ad[1]:.2f} s "
              f"({ad[1] / t_r:.0f}x the residual), compile {ad[0]:.1f} s; max rel. diff to the sensitivity Jacobian {ad[2]:.1e}")
    return dict(jflex=[(j["label"], j["t"], j["cost"]) for j in jrows], scipy=[(r["label"], r["t"], r["cost"]) for r in srows])


if __name__ == "__main__":
    main()
