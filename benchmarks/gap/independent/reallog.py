"""Gap-bench cases with the traits of real robot logs, made by independent code (Pinocchio, SciPy,
NumPy; nothing from jflex).

Every case is a folder a user could have written: ``case.yaml`` in the case format of
docs/case_format.md, the nominal (CAD) robot as URDF, the records as NPZ or, where the trait is
about the log file itself (stamps, currents), as CSV; and ``truth.json`` for the scorer only.

One function per trait family; :func:`make_reallog_case` dispatches, :func:`plan` lists the
family's cases. The traits:

``closed_loop``       a PID controller with a CAD feed-forward tracks a Fourier reference on the
                      true robot (Pinocchio's ABA integrated by SciPy); the logged torque is the
                      controller's command, the logged angles the robot's (not the reference's)
``currents``          motor currents instead of torques; the case's torque constants are data-sheet
                      values a few per cent off; gear ratios; per-joint current offsets (stated in
                      case.yaml, as a zero-current calibration gives them); planted: Coulomb friction
``coupled_wrist``     as ``currents``, the last two joints driven by two motors through a coupling
                      matrix ``K``: ``tau = K^T k (i - i0)``; planted: the coupled motor's own
                      friction (a coupled drive)
``forgotten_scale``   a currents log whose case.yaml forgets the current-to-torque scale
``jitter``            CSV stamps jittering by 20 % of the step, dropped samples, repeated rows (same
                      stamp) and stale rows (the previous values at a new stamp)
``jitter_twin``       the same robot, effect and motion sampled uniformly (the diagnosis of
                      ``jitter`` should be this one's)
``dead_zero``         one joint's torque channel reads exact zeros 85 % of the time
``dead_stuck``        one joint's torque channel is stuck at 0.013 N m
``drifting_friction`` one joint's viscous friction drifts by 30 % over the session
``multirate``         training records at 250 Hz, the validation record at 1 kHz
``periodic``          a periodic excitation repeated over several periods, white noise of known std
``null_cad_ar1``      nothing planted: masses 10 % off the CAD and AR(1) coloured noise (2 %)
``cogging``           a position-dependent cogging torque under closed-loop tracking (out of the
                      library: the right answer is ``unexplained``)
``velocities``        a jittered 1 kHz log with encoder-differenced velocities and no accelerations
"""

from __future__ import annotations

import csv
import json
import pathlib

import numpy as np
import pinocchio as pin
import yaml
from scipy.integrate import solve_ivp

from . import robots as R
from . import signals as S
from .torque import COULOMB_WIDTH, rnea_batch

TRAITS = ("closed_loop", "currents", "coupled_wrist", "forgotten_scale", "jitter", "jitter_twin", "dead_zero",
          "dead_stuck", "drifting_friction", "multirate", "periodic", "null_cad_ar1", "cogging", "velocities")
JITTER = 0.2          # steps vary by up to +-20 % of the nominal step
DROP_FRACTION = 0.02  # samples dropped one by one, besides one burst
DROP_BURST = 3        # consecutive samples lost once per record (one step of ~4 x the nominal one)
REPEAT_FRACTION = 0.01  # rows logged twice (same stamp, same values)
STALE_FRACTION = 0.01   # rows that repeat the previous row's values at their own stamp (a stale reading)
DEAD_FRACTION = 0.85  # share of exact zeros on a dead channel
STUCK_VALUE = 0.013   # [N m] a stuck channel's constant reading
DRIFT = 0.30          # viscous friction grows by this fraction over the session
ENCODER_STEP = 2 * np.pi / 2**19
# "current": case.yaml as docs/case_format.md had it when this family was written (one CSV per
# record; scale per column only); "extended": the fields for real robots (a list of CSV files
# merged on time, current offsets, a coupling matrix); the currents and jitter cases read it
CASE_FORMAT = "extended"


# --- the physics ----------------------------------------------------------------------------------
def planted_torque(effects, q, qd, s):
    """Torque (N, n) the planted effects add along the motion; ``s`` (N,) is the session time
    [s] (only a drift reads it). ``effects``: dicts with ``effect``, ``j`` (joint index), ``params``."""
    out = np.zeros_like(qd)
    for e in effects:
        j, p = e["j"], e["params"]
        if e["effect"] == "viscous_friction":
            out[:, j] += p["Fv"] * qd[:, j]
        elif e["effect"] == "coulomb_friction":
            out[:, j] += p["Fc"] * np.tanh(qd[:, j] / COULOMB_WIDTH)
        elif e["effect"] == "cogging":
            out[:, j] += p["A"] * np.sin(p["periods"] * q[:, j] + p["phase"])
        elif e["effect"] == "coupled_drive":
            # friction of motor j, whose shaft also turns with joint a: w = qd_j + c qd_a (joint-side
            # units); its torque reaches both joints through the coupling row [c, 1]
            w = qd[:, j] + p["c"] * qd[:, p["a"]]
            f = p["fv"] * w + p["fc"] * np.tanh(w / COULOMB_WIDTH)
            out[:, j] += f
            out[:, p["a"]] += p["c"] * f
        elif e["effect"] == "friction_drift":
            # the viscous coefficient grows linearly over the session, from Fv0 to (1 + DRIFT) Fv0
            out[:, j] += p["Fv0"] * DRIFT * (s - p["s0"]) / (p["s1"] - p["s0"]) * qd[:, j]
        else:
            raise KeyError(f"unknown planted effect {e['effect']!r}")
    return out


def friction(Fv, Fc, qd):
    """The every-joint friction of the true robot (viscous + tanh Coulomb), (N, n)."""
    return Fv[None] * qd + Fc[None] * np.tanh(qd / COULOMB_WIDTH)


def open_loop(true, traj, t, fric, effects, s=None):
    """Motor torques of the true robot following ``traj`` exactly at times ``t``: q, qd, qdd, tau."""
    q, qd, qdd = traj(t), traj(t, 1), traj(t, 2)
    tau = rnea_batch(true, q, qd, qdd) + friction(*fric, qd) + planted_torque(effects, q, qd, t if s is None else s)
    return q, qd, qdd, tau


class PID:
    """Joint-space PID with the CAD model's inverse dynamics of the reference as feed-forward:
    ``u = rnea_cad(r, r', r'') + Kp e + Kd e' + Ki int e``, ``e = r - q``. Gains per joint from the
    true robot's diagonal inertia at ``home`` for a ``bandwidth_hz`` loop (damping 0.7)."""

    def __init__(self, true, cad, traj, home, bandwidth_hz=4.0):
        self.cad, self.traj, self.data = cad, traj, cad.createData()
        m = np.diag(pin.crba(true, true.createData(), home)).copy()
        w = 2 * np.pi * bandwidth_hz
        self.Kp, self.Kd, self.Ki = m * w**2, 2 * 0.7 * m * w, m * w**3 / 10

    def __call__(self, t, q, qd, z):
        r, rd, rdd = reference(self.traj, t)
        ff = pin.rnea(self.cad, self.data, r, rd, rdd)
        return ff + self.Kp * (r - q) + self.Kd * (rd - qd) + self.Ki * z


def reference(traj, t):
    """Angle, rate and acceleration of the Fourier trajectory ``traj`` at one time ``t`` (the
    closed loop's inner call: one sine and cosine per harmonic instead of three)."""
    s, c = np.sin(traj.w * t), np.cos(traj.w * t)
    w = traj.w
    return (traj.c + traj.a @ s + traj.b @ c, traj.a @ (w * c) - traj.b @ (w * s),
            -(traj.a @ (w * w * s) + traj.b @ (w * w * c)))


def closed_loop(true, cad, traj, home, t, fric, effects, rtol=1e-8, atol=1e-10):
    """Simulate the PID-controlled true robot (``pin.aba``, ``solve_ivp`` DOP853) from the
    reference's state at ``t[0]``. Returns q, qd, qdd (the plant's, by ABA) and u (the command)
    at ``t``, and the reference's angles there."""
    n = true.nq
    ctrl = PID(true, cad, traj, home)
    data = true.createData()
    Fv, Fc = fric

    def parts(tt, x):
        q, qd, z = x[:n], x[n:2 * n], x[2 * n:]
        u = ctrl(tt, q, qd, z)
        load = friction(Fv, Fc, qd[None])[0] + planted_torque(effects, q[None], qd[None], np.array([tt]))[0]
        qdd = pin.aba(true, data, q, qd, u - load).copy()
        return q, qd, qdd, u, reference(traj, tt)[0] - q

    def rhs(tt, x):
        _, qd, qdd, _, e = parts(tt, x)
        return np.concatenate([qd, qdd, e])

    x0 = np.concatenate([traj(t[0])[0], traj(t[0], 1)[0], np.zeros(n)])
    sol = solve_ivp(rhs, (t[0], t[-1]), x0, method="DOP853", t_eval=t, rtol=rtol, atol=atol, max_step=0.05)
    if not sol.success:
        raise RuntimeError(f"closed-loop simulation failed: {sol.message}")
    out = [parts(tt, x) for tt, x in zip(sol.t, sol.y.T)]
    q, qd, qdd, u = (np.stack([o[k] for o in out]) for k in range(4))
    return q, qd, qdd, u, traj(t)


# --- currents -------------------------------------------------------------------------------------
def current_map(n, gear, k, coupled=None, c=0.0):
    """The transmission matrix ``K`` (motor rates = K joint rates) and the torque constants
    ``k`` [N m/A]. ``coupled=(a, b)``: motor b also turns with joint a, ``theta_b = g_b (q_b + c q_a)``
    (a wrist whose last motor's shaft passes through the previous joint)."""
    K = np.diag(np.asarray(gear, float))
    if coupled is not None:
        a, b = coupled
        K[b, a] = c * gear[b]
    return K, np.asarray(k, float)


def torque_from_current(K, k, i, i0):
    """``tau = K^T k (i - i0)``, row by row: (N, n)."""
    return ((i - i0) * k[None]) @ K


def current_from_torque(K, k, tau, i0):
    """The currents that give ``tau``: ``i = k^-1 K^-T tau + i0``."""
    return np.linalg.solve(K.T, tau.T).T / k[None] + i0


# --- time stamps ----------------------------------------------------------------------------------
def jittered_stamps(rng, T, fs, jitter=JITTER, drops=DROP_FRACTION, burst=DROP_BURST, repeats=REPEAT_FRACTION):
    """Stamps of a log at nominal rate ``fs`` over ``[0, T)``: each stamp off its grid point by up
    to ``jitter / 2`` steps (so steps vary by up to ``jitter``), a fraction ``drops`` of samples
    dropped one by one plus one burst of ``burst``, and a fraction ``repeats`` of rows logged
    twice. Returns ``(stamps, index of each row into the unique stamps)``: rows repeat stamps."""
    h = 1.0 / fs
    N = int(round(T * fs))
    t = np.arange(N) * h + rng.uniform(-jitter / 2, jitter / 2, N) * h
    t[0] = 0.0
    keep = rng.random(N) >= drops
    b0 = int(rng.integers(N // 4, 3 * N // 4))
    keep[b0:b0 + burst] = False
    keep[[0, -1]] = True
    # a dropped sample next to another leaves gaps of 2-3 steps; never drop two singles in a row
    # outside the burst, so the largest gap is the burst's
    for k in range(1, N - 1):
        if not keep[k] and not keep[k - 1] and not (b0 <= k < b0 + burst):
            keep[k] = True
    t = t[keep]
    rows = np.arange(t.size)
    rep = np.flatnonzero(rng.random(t.size) < repeats)
    rows = np.sort(np.concatenate([rows, rep]))
    return t, rows


# --- case folders ---------------------------------------------------------------------------------
def _setup(robot, rng, mass_pct=(2.0, 10.0), com_m=(0.005, 0.02)):
    true, tool, home = R.true_model(robot)
    cad, caderr = R.cad_error(true, rng, mass_pct, com_m)
    return true, tool, home, cad, caderr


def _trajs(rng, true, home, T, count=3, harmonics=5):
    n = true.nq
    lo, hi = true.lowerPositionLimit, true.upperPositionLimit
    amp = np.minimum(0.6 if n == 3 else 0.45, 0.9 * np.minimum(home - lo, hi - home))
    return [S.Fourier(rng, home + rng.uniform(-0.1, 0.1, n), amp, f0=1.0 / T, harmonics=harmonics) for _ in range(count)]


def _friction(rng, true, traj, T):
    t = np.linspace(0, T, 400)
    q, qd, qdd = traj(t), traj(t, 1), traj(t, 2)
    scale = rnea_batch(true, q, qd, qdd).std(axis=0)
    Fv = rng.uniform(0.03, 0.08, true.nq) * scale / qd.std(axis=0)
    Fc = rng.uniform(0.03, 0.08, true.nq) * scale
    return Fv, Fc, scale, qd.std(axis=0)


def _write_csv(path, header, cols):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        for row in zip(*cols):
            w.writerow([f"{v:.10g}" for v in row])


def _case_yaml(folder, datasets, tool, true, fric, notes=None):
    """case.yaml: the nominal friction laws at the joints whose true robot has them (a planted
    friction replaces the nominal law at its joint, so that joint's law is not nominal)."""
    nominal = []
    for law, vals in (("viscous_friction", fric[0]), ("coulomb_friction", fric[1])):
        js = [true.names[k + 1] for k in range(true.nq) if vals[k] > 0]
        if js:
            nominal.append(dict(effect=law, joint="all" if len(js) == true.nq else js))
    cfg = dict(robot="robot.urdf", tool_frame=tool, nominal_effects=nominal, datasets=datasets)
    if notes:
        cfg["notes"] = notes
    (folder / "case.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))


def _finish(folder, cad, tool, robot, truth):
    (folder / "robot.urdf").write_text(R.urdf_text(cad, tool, robot))
    (folder / "truth.json").write_text(json.dumps(truth, indent=1, default=float))
    return folder, truth


def _noise(rng, tau, pct, pole=0.7, ref=None):
    std = pct / 100 * (tau.std(axis=0) if ref is None else ref)
    return S.ar1_noise(rng, tau.shape, pole, std), std


def _effect(rng, true, name, j, scale, qdstd, fric, r=None):
    """A planted effect of 10-15 % of joint ``j``'s torque std; a planted friction law replaces
    the every-joint one at ``j`` (``fric = (Fv, Fc)`` is zeroed there, in place)."""
    r = rng.uniform(0.10, 0.15) if r is None else r
    if name == "viscous_friction":
        p = {"Fv": float(r * scale[j] / qdstd[j])}
        fric[0][j] = 0.0
    elif name == "coulomb_friction":
        p = {"Fc": float(r * scale[j])}
        fric[1][j] = 0.0
    elif name == "cogging":
        p = {"A": float(r * scale[j]), "periods": float(rng.uniform(15, 30)), "phase": float(rng.uniform(0, 2 * np.pi))}
    else:
        raise KeyError(name)
    return dict(effect=name, j=j, params=p)


def _truth(true, robot, trait, family, effects, expected, noise_std, **extra):
    te = [dict(effect=e["effect"], joint=None if e["effect"] == "coupled_drive" else true.names[e["j"] + 1],
               params=dict(e["params"], joints=[true.names[e["params"]["a"] + 1], true.names[e["j"] + 1]])
               if e["effect"] == "coupled_drive" else e["params"],
               in_library=e["effect"] not in ("cogging", "friction_drift")) for e in effects]
    return dict(kind="torque", robot=robot, trait=trait, family=family, effects=te, expected_verdict=expected,
                noise_std_nm={true.names[k + 1]: float(v) for k, v in enumerate(noise_std)}, dead_channels=[], **extra)


def _npz_datasets(folder, recs):
    ds = []
    for name, split, arrays in recs:
        np.savez(folder / f"{name}.npz", **arrays)
        ds.append(dict(kind="torque", file=f"{name}.npz", split=split))
    return ds


def _records(rng, true, trajs, fric, effects, T, fs, noise_pct, cad=None, home=None, pole=0.7, ref=None, tracking=None):
    """Three records (two train, one validation), open loop, or closed loop when ``cad`` is given.
    Returns the records and the torque noise std (per joint, of the validation record); a closed
    loop's largest tracking error per record and joint [rad] goes to ``tracking`` (when a list)."""
    t = np.arange(int(round(T * fs))) / fs
    recs, std = [], None
    for i, tr in enumerate(trajs):
        s = t + i * T
        if cad is None:
            q, qd, qdd, tau = open_loop(true, tr, t, fric, effects, s)
        else:
            q, qd, qdd, tau, r = closed_loop(true, cad, tr, home, t, fric, effects)
            if tracking is not None:
                tracking.append(np.abs(q - r).max(axis=0).tolist())
        e, std = _noise(rng, tau, noise_pct, pole, ref)
        recs.append((f"traj{i}", "train" if i < 2 else "validation",
                     dict(t=t, q=S.quantise(q, ENCODER_STEP), tau=tau + e)))
    return recs, std


def _pick_joint(rng, n, avoid=()):
    return int(rng.choice([k for k in range(n) if k not in avoid]))


def case_closed_loop(folder, robot="arm3", seed=0, small=True, cogging=False):
    """A PID tracks a Fourier reference; the logged torque is the command. Planted: viscous
    friction at one joint (``cogging``: a cogging torque instead, out of the library)."""
    rng = np.random.default_rng(seed)
    true, tool, home, cad, caderr = _setup(robot, rng)
    T, fs = (4.0 if small else 6.0), 500.0
    trajs = _trajs(rng, true, home, T)
    Fv, Fc, scale, qdstd = _friction(rng, true, trajs[0], T)
    j = _pick_joint(rng, true.nq)
    eff = [_effect(rng, true, "cogging" if cogging else "viscous_friction", j, scale, qdstd, (Fv, Fc))]
    tracking = []
    recs, std = _records(rng, true, trajs, (Fv, Fc), eff, T, fs, 1.0, cad=cad, home=home, tracking=tracking)
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    _case_yaml(folder, _npz_datasets(folder, recs), tool, true, (Fv, Fc))
    trait = "cogging" if cogging else "closed_loop"
    truth = _truth(true, robot, trait, "out_of_library" if cogging else "single", eff,
                   "unexplained" if cogging else "explained", std, cad_error=caderr,
                   realism=dict(fs_hz=fs, controller="PID + CAD feed-forward, 4 Hz",
                                tracking_error_max_rad=tracking, friction_Fv=Fv.tolist(),
                                friction_Fc=Fc.tolist(), torque_std=scale.tolist()))
    return _finish(folder, cad, tool, robot, truth)


def case_cogging(folder, robot="arm3", seed=0, small=True):
    return case_closed_loop(folder, robot, seed, small, cogging=True)


def case_currents(folder, robot="arm3", seed=0, small=True, coupled=False, forget_scale=False, fmt=None):
    """Motor currents in a CSV per record; case.yaml's scale is data-sheet constant x gear ratio
    (the constants 2-5 % off the true ones). Per-joint current offsets ``i0``. ``coupled``: the last
    two joints share a coupling (``tau = K^T k (i - i0)``). ``forget_scale``: no scale at all.
    ``fmt`` (default ``CASE_FORMAT``): ``extended`` states the offsets and the coupling in
    case.yaml; ``current`` leaves them to ``transmission.json`` (the diagonal scale only)."""
    fmt = fmt or CASE_FORMAT
    rng = np.random.default_rng(seed)
    true, tool, home, cad, caderr = _setup(robot, rng)
    n = true.nq
    T, fs = (4.0 if small else 6.0), 500.0
    trajs = _trajs(rng, true, home, T)
    Fv, Fc, scale, qdstd = _friction(rng, true, trajs[0], T)
    gear = rng.choice([50.0, 80.0, 100.0, 120.0, 160.0], n)
    k_true = rng.uniform(0.05, 0.2, n)
    k_sheet = k_true * (1 + rng.choice([-1.0, 1.0], n) * rng.uniform(0.02, 0.05, n))
    i0 = rng.uniform(-0.05, 0.05, n)
    cpl = (n - 2, n - 1) if coupled else None
    c = float(rng.choice([0.5, 1.0])) if coupled else 0.0  # joint-side coupling ratio (a Staubli TX wrist: 1)
    K, k = current_map(n, gear, k_true, cpl, c=c)
    if forget_scale:
        eff = []
    elif coupled:
        # the coupled motor's own friction, as identified on a real coupled wrist: 10-15 % of the
        # last joint's torque std, half viscous, half Coulomb
        a, b = cpl
        r = rng.uniform(0.10, 0.15)
        wstd = np.hypot(qdstd[b], c * qdstd[a])
        eff = [dict(effect="coupled_drive", j=b, params={"a": a, "c": c, "fv": float(0.5 * r * scale[b] / wstd),
                                                          "fc": float(0.5 * r * scale[b])})]
    else:
        eff = [_effect(rng, true, "coulomb_friction", _pick_joint(rng, n), scale, qdstd, (Fv, Fc))]
    recs, std = _records(rng, true, trajs, (Fv, Fc), eff, T, fs, 1.0)
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    names = [true.names[m + 1] for m in range(n)]
    ds = []
    for name, split, a in recs:
        cur = current_from_torque(K, k, a["tau"], i0)
        hdr = ["time"] + [f"{m}_pos" for m in names] + [f"motor{m + 1}_current" for m in range(n)]
        _write_csv(folder / f"{name}.csv", hdr, [a["t"], *a["q"].T, *cur.T])
        d = dict(kind="torque", file=f"{name}.csv", split=split,
                 columns=dict(time="time", position={m: f"{m}_pos" for m in names},
                              torque={m: f"motor{r + 1}_current" for r, m in enumerate(names)}))
        col = [f"motor{r + 1}_current" for r in range(n)]
        if not forget_scale:
            # what a user writes from the data sheets: constant x gear, or at a coupled motor the
            # constant alone (the coupling matrix holds its gear)
            d["scale"] = {col[r]: float(k_sheet[r] * (1.0 if fmt == "extended" and cpl and r in cpl else gear[r]))
                          for r in range(n)}
        if fmt == "extended":
            d["offset"] = {col[r]: float(i0[r]) for r in range(n)}
            if cpl:
                d["coupling"] = dict(joints=[names[m] for m in cpl], matrix=K[np.ix_(cpl, cpl)].tolist())
        ds.append(d)
    trans = dict(K=K.tolist(), torque_constant_true=k_true.tolist(), torque_constant_datasheet=k_sheet.tolist(),
                 gear=gear.tolist(), current_offset_a=i0.tolist(), coupled_joints=[names[m] for m in cpl] if cpl else [])
    # the transmission as a user knows it (data-sheet constants, measured zero-current offsets,
    # the coupling from the drawings), for a case format that can state it
    (folder / "transmission.json").write_text(json.dumps(
        dict(K=K.tolist(), torque_constant=k_sheet.tolist(), gear=gear.tolist(), current_offset_a=i0.tolist(),
             coupled_joints=trans["coupled_joints"]), indent=1))
    gaps = [] if fmt == "extended" else ["current offsets"] + (["coupled transmission"] if coupled else [])
    notes = ("motor currents; " + " and ".join(gaps) + " in transmission.json (tau = K^T k (i - i0))") if gaps else None
    _case_yaml(folder, ds, tool, true, (Fv, Fc), notes)
    trait = "forgotten_scale" if forget_scale else ("coupled_wrist" if coupled else "currents")
    truth = _truth(true, robot, trait, "forgotten_scale" if forget_scale else "single", eff,
                   "not_explained" if forget_scale else "explained", std, cad_error=caderr, transmission=trans,
                   case_format=fmt, format_gaps=gaps,
                   realism=dict(fs_hz=fs, friction_Fv=Fv.tolist(), friction_Fc=Fc.tolist(), torque_std=scale.tolist()))
    return _finish(folder, cad, tool, robot, truth)


def case_jitter(folder, robot="arm3", seed=0, small=True, twin=False, fmt=None, velocity=False):
    """CSV logs whose stamps jitter by 20 % with dropped samples and repeated rows (``twin``: the
    same case sampled uniformly). Planted: viscous friction at one joint. The topics (positions,
    velocities, efforts: one CSV each, as a ROS-derived export) are written under ``raw/``; with
    ``fmt`` ``extended`` case.yaml names the position and effort files of each record (merged on
    time), else one merged CSV per record. ``velocity``: a 1 kHz log whose case also reads the
    logged velocities (encoder-differenced: 3e-3 rad/s of noise, about 4 rad/s^2 once
    differentiated again) and no accelerations."""
    fmt = fmt or CASE_FORMAT
    rng = np.random.default_rng(seed)
    true, tool, home, cad, caderr = _setup(robot, rng)
    n = true.nq
    T, fs = (4.0 if small else 6.0), (1000.0 if velocity else 500.0)
    vel_noise = 3e-3 if velocity else 1e-3
    trajs = _trajs(rng, true, home, T)
    Fv, Fc, scale, qdstd = _friction(rng, true, trajs[0], T)
    eff = [_effect(rng, true, "viscous_friction", _pick_joint(rng, n), scale, qdstd, (Fv, Fc))]
    srng = np.random.default_rng(seed + 10_000)  # the stamps' draws apart: the twin's physics is the same
    nrng = np.random.default_rng(seed + 20_000)
    folder = pathlib.Path(folder)
    (folder / "raw").mkdir(parents=True, exist_ok=True)
    names = [true.names[m + 1] for m in range(n)]
    ds, stats = [], []
    for i, tr in enumerate(trajs):
        if twin:
            t, rows = np.arange(int(round(T * fs))) / fs, None
        else:
            t, rows = jittered_stamps(srng, T, fs)
        q, qd, qdd, tau = open_loop(true, tr, t, (Fv, Fc), eff, t + i * T)
        tau = tau + S.ar1_noise(nrng, tau.shape, 0.7, 0.01 * scale)
        qm = S.quantise(q, ENCODER_STEP)
        qdm = qd + nrng.normal(0, vel_noise, qd.shape)
        if rows is not None:
            stale = np.flatnonzero(srng.random(t.size) < STALE_FRACTION)
            stale = stale[stale > 0]
            for k in stale:  # in order: a run of stale rows holds the last fresh reading
                qm[k], qdm[k], tau[k] = qm[k - 1], qdm[k - 1], tau[k - 1]
            t, qm, qdm, tau = t[rows], qm[rows], qdm[rows], tau[rows]
            dt = np.diff(t)
            stats.append(dict(rows=int(t.size), repeated_rows=int(np.sum(dt == 0)), stale_rows=int(stale.size),
                              max_step_over_nominal=float(dt.max() * fs),
                              jitter_of_kept_steps=float(np.max(np.abs(dt[(dt > 0) & (dt < 1.5 / fs)] * fs - 1)))))
        name = f"traj{i}"
        vcols = [f"{m}_vel" for m in names] if velocity else []
        hdr = ["time"] + [f"{m}_pos" for m in names] + vcols + [f"{m}_effort" for m in names]
        _write_csv(folder / f"{name}.csv", hdr, [t, *qm.T, *(qdm.T if velocity else []), *tau.T])
        for topic, suf, arr in (("position", "pos", qm), ("velocity", "vel", qdm), ("effort", "effort", tau)):
            _write_csv(folder / "raw" / f"{name}_{topic}.csv", ["time"] + [f"{m}_{suf}" for m in names], [t, *arr.T])
        topics = ["position"] + (["velocity"] if velocity else []) + ["effort"]
        files = [f"raw/{name}_{tp}.csv" for tp in topics] if fmt == "extended" else f"{name}.csv"
        cols = dict(time="time", position={m: f"{m}_pos" for m in names})
        if velocity:
            cols["velocity"] = {m: f"{m}_vel" for m in names}
        cols["torque"] = {m: f"{m}_effort" for m in names}
        ds.append(dict(kind="torque", file=files, split="train" if i < 2 else "validation", columns=cols))
    _case_yaml(folder, ds, tool, true, (Fv, Fc))
    trait = "velocities" if velocity else ("jitter_twin" if twin else "jitter")
    truth = _truth(true, robot, trait, "single", eff, "explained", 0.01 * scale,
                   cad_error=caderr, stamps=stats, nominal_rate_hz=fs,
                   realism=dict(fs_hz=fs, jitter=0.0 if twin else JITTER, velocity_noise_rad_s=vel_noise if velocity else None,
                                friction_Fv=Fv.tolist(), friction_Fc=Fc.tolist(), torque_std=scale.tolist()))
    return _finish(folder, cad, tool, robot, truth)


def case_dead(folder, robot="arm3", seed=0, small=True, stuck=False):
    """One joint's torque channel is dead: exact zeros 85 % of the samples (``stuck``: a constant
    0.013 N m). Planted: viscous friction at the shoulder (joint index 1)."""
    rng = np.random.default_rng(seed)
    true, tool, home, cad, caderr = _setup(robot, rng)
    n = true.nq
    T, fs = (4.0 if small else 6.0), 500.0
    trajs = _trajs(rng, true, home, T)
    Fv, Fc, scale, qdstd = _friction(rng, true, trajs[0], T)
    eff = [_effect(rng, true, "viscous_friction", 1, scale, qdstd, (Fv, Fc))]
    recs, std = _records(rng, true, trajs, (Fv, Fc), eff, T, fs, 1.0)
    dead = n - 1
    for _, _, a in recs:
        if stuck:
            a["tau"][:, dead] = STUCK_VALUE
        else:
            a["tau"][rng.random(a["tau"].shape[0]) < DEAD_FRACTION, dead] = 0.0
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    _case_yaml(folder, _npz_datasets(folder, recs), tool, true, (Fv, Fc))
    truth = _truth(true, robot, "dead_stuck" if stuck else "dead_zero", "single", eff, "explained", std, cad_error=caderr,
                   realism=dict(fs_hz=fs, friction_Fv=Fv.tolist(), friction_Fc=Fc.tolist(), torque_std=scale.tolist()))
    truth["dead_channels"] = [dict(joint=true.names[dead + 1], kind="stuck" if stuck else "zeros",
                                   value=STUCK_VALUE if stuck else 0.0, fraction=1.0 if stuck else DEAD_FRACTION)]
    return _finish(folder, cad, tool, robot, truth)


def case_drifting_friction(folder, robot="arm3", seed=0, small=True):
    """One joint's viscous friction grows by 30 % over the session (train, train, validation in
    that order); the nominal model holds a constant viscous friction at every joint."""
    rng = np.random.default_rng(seed)
    true, tool, home, cad, caderr = _setup(robot, rng)
    n = true.nq
    T, fs = (6.0 if small else 15.0), 500.0
    trajs = _trajs(rng, true, home, T)
    Fv, Fc, scale, qdstd = _friction(rng, true, trajs[0], T)
    j = _pick_joint(rng, n)
    Fv[j] = rng.uniform(0.15, 0.25) * scale[j] / qdstd[j]  # a joint whose viscous friction matters
    eff = [dict(effect="friction_drift", j=j, params={"Fv0": float(Fv[j]), "s0": 0.0, "s1": 3 * T, "drift": DRIFT})]
    recs, std = _records(rng, true, trajs, (Fv, Fc), eff, T, fs, 0.5)
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    _case_yaml(folder, _npz_datasets(folder, recs), tool, true, (Fv, Fc))
    truth = _truth(true, robot, "drifting_friction", "drift", eff, "not_within_noise", std, cad_error=caderr,
                   realism=dict(fs_hz=fs, friction_Fv=Fv.tolist(), friction_Fc=Fc.tolist(), torque_std=scale.tolist()))
    return _finish(folder, cad, tool, robot, truth)


def case_multirate(folder, robot="arm3", seed=0, small=True):
    """Training records at 250 Hz, the validation record at 1 kHz. Planted: Coulomb friction."""
    rng = np.random.default_rng(seed)
    true, tool, home, cad, caderr = _setup(robot, rng)
    T = 4.0 if small else 6.0
    trajs = _trajs(rng, true, home, T)
    Fv, Fc, scale, qdstd = _friction(rng, true, trajs[0], T)
    eff = [_effect(rng, true, "coulomb_friction", _pick_joint(rng, true.nq), scale, qdstd, (Fv, Fc))]
    recs = []
    for i, (tr, fs) in enumerate(zip(trajs, (250.0, 250.0, 1000.0))):
        r, std = _records(rng, true, [tr], (Fv, Fc), eff, T, fs, 1.0, ref=scale)
        (_, _, a), = r
        recs.append((f"traj{i}_{int(fs)}hz", "train" if i < 2 else "validation", a))
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    _case_yaml(folder, _npz_datasets(folder, recs), tool, true, (Fv, Fc))
    truth = _truth(true, robot, "multirate", "single", eff, "explained", std, cad_error=caderr,
                   realism=dict(fs_hz=[250.0, 250.0, 1000.0], friction_Fv=Fv.tolist(), friction_Fc=Fc.tolist(),
                                torque_std=scale.tolist()))
    return _finish(folder, cad, tool, robot, truth)


def case_periodic(folder, robot="arm3", seed=0, small=True):
    """Nothing planted; each record repeats one period of a Fourier excitation several times
    (``periods``), white torque noise of a known std per joint (``noise_std_nm`` in the truth): the
    scatter between periods is that noise alone."""
    rng = np.random.default_rng(seed)
    true, tool, home, cad, caderr = _setup(robot, rng)
    P, periods, fs = 2.0, (4 if small else 6), 500.0
    trajs = _trajs(rng, true, home, P)
    Fv, Fc, scale, qdstd = _friction(rng, true, trajs[0], P)
    std = rng.uniform(0.5, 2.0, true.nq) / 100 * scale
    t = np.arange(int(round(periods * P * fs))) / fs
    recs = []
    for i, tr in enumerate(trajs):
        q, qd, qdd, tau = open_loop(true, tr, t, (Fv, Fc), [])
        recs.append((f"traj{i}", "train" if i < 2 else "validation",
                     dict(t=t, q=S.quantise(q, ENCODER_STEP), tau=tau + rng.normal(size=tau.shape) * std[None])))
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    _case_yaml(folder, _npz_datasets(folder, recs), tool, true, (Fv, Fc))
    truth = _truth(true, robot, "periodic", "null", [], "within_noise", std, cad_error=caderr,
                   period_s=P, periods=periods, samples_per_period=int(round(P * fs)),
                   noise_pct_of_torque_std=(100 * std / scale).tolist(),
                   realism=dict(fs_hz=fs, noise="white", friction_Fv=Fv.tolist(), friction_Fc=Fc.tolist(),
                                torque_std=scale.tolist()))
    return _finish(folder, cad, tool, robot, truth)


def case_null_cad_ar1(folder, robot="arm3", seed=0, small=True):
    """Nothing planted: every link's mass (and rotational inertia) 10 % off in the CAD, centres of
    mass exact, AR(1) torque noise of 2 % of each joint's torque std."""
    rng = np.random.default_rng(seed)
    true, tool, home, cad, caderr = _setup(robot, rng, mass_pct=(10.0, 10.0), com_m=(0.0, 0.0))
    T, fs = (4.0 if small else 6.0), 500.0
    trajs = _trajs(rng, true, home, T)
    Fv, Fc, scale, qdstd = _friction(rng, true, trajs[0], T)
    pole = float(rng.uniform(0.7, 0.9))
    recs, std = _records(rng, true, trajs, (Fv, Fc), [], T, fs, 2.0, pole=pole)
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    _case_yaml(folder, _npz_datasets(folder, recs), tool, true, (Fv, Fc))
    truth = _truth(true, robot, "null_cad_ar1", "null", [], "within_noise", std, cad_error=caderr,
                   realism=dict(fs_hz=fs, noise_pct=2.0, noise_ar1_pole=pole, friction_Fv=Fv.tolist(),
                                friction_Fc=Fc.tolist(), torque_std=scale.tolist()))
    return _finish(folder, cad, tool, robot, truth)


_MAKERS = {  # trait -> (function, its keyword arguments); the functions that write CSV take the format
    "closed_loop": (case_closed_loop, {}), "cogging": (case_cogging, {}),
    "currents": (case_currents, {"fmt": None}), "coupled_wrist": (case_currents, {"coupled": True, "fmt": None}),
    "forgotten_scale": (case_currents, {"forget_scale": True, "fmt": None}),
    "jitter": (case_jitter, {"fmt": None}), "jitter_twin": (case_jitter, {"twin": True, "fmt": None}),
    "dead_zero": (case_dead, {}), "dead_stuck": (case_dead, {"stuck": True}),
    "drifting_friction": (case_drifting_friction, {}), "multirate": (case_multirate, {}), "periodic": (case_periodic, {}),
    "null_cad_ar1": (case_null_cad_ar1, {}),
    "velocities": (case_jitter, {"velocity": True, "fmt": None}),
}


def make_reallog_case(folder, trait, seed=0, small=True, robot=None, fmt=None) -> tuple[pathlib.Path, dict]:
    """Write the case folder of one trait (see the module's docstring); ``robot`` arm3 | ur5 |
    panda (default: the plan's choice, arm3 at the small size); ``fmt`` the case format of the
    CSV cases, ``current`` or ``extended`` (default ``CASE_FORMAT``). Returns ``(folder, truth)``."""
    if trait not in _MAKERS:
        raise ValueError(f"trait: expected one of {TRAITS}, got {trait!r}")
    if fmt not in (None, "current", "extended"):
        raise ValueError(f"fmt: expected 'current' or 'extended', got {fmt!r}")
    robot = robot or _robot_for(trait, "small" if small else "full")
    fn, kw = _MAKERS[trait]
    kw = {k: (fmt if k == "fmt" else v) for k, v in kw.items()}
    return fn(folder, robot, seed, small, **kw)


def _robot_for(trait, size):
    if size == "small":
        return "arm3"
    return {"coupled_wrist": "ur5", "dead_zero": "ur5", "dead_stuck": "ur5", "drifting_friction": "panda",
            "null_cad_ar1": "ur5", "jitter": "panda", "jitter_twin": "panda", "velocities": "panda"}.get(trait, "arm3")


def plan(size: str = "small") -> list[dict]:
    """The family's cases: ``id``, ``trait``, ``robot``, ``seed``, ``small``. ``small``: every trait
    once on the 3-joint arm, short records; ``full``: every trait on the robot its real log came
    from (UR5 for the dead channels and the coupled wrist, Panda for jitter and drift), long records."""
    out = []
    for i, trait in enumerate(TRAITS):
        # the twin shares its jitter case's seed: same robot, effect and motion
        seed = 9100 + 13 * (i - 1 if trait == "jitter_twin" else i) + (0 if size == "small" else 1000)
        out.append(dict(id=f"r{i:02d}_{trait}", trait=trait, robot=_robot_for(trait, size), seed=seed,
                        small=size == "small"))
    return out
