"""Case folders of the independent bench: ``case.yaml``, the nominal (CAD) robot as URDF, NPZ data
(train and validation) and ``truth.json`` (read by the scorer only, never named in case.yaml).

Realism drawn per case: CAD masses 2-10 % off and COMs 0.5-2 cm off (the data come from the true
robot); torque records with angles only, quantised to 2 pi / 2^18..2^20 rad, sampled at
200-1000 Hz, AR(1) torque noise of 0.5-2 % of each joint's torque std and, in some cases, a
sub-sample delay between angles and torques; FRFs estimated by H1 from a simulated random test
with input and output noise; modal tables with 0.5-1 % frequency noise.
"""

from __future__ import annotations

import json
import pathlib

import numpy as np
import pinocchio as pin
import yaml

from . import frf as F
from . import robots as R
from . import signals as S
from . import tip as TP
from . import torque as TQ

IN_LIBRARY_TORQUE = ("viscous_friction", "coulomb_friction", "stribeck_friction", "rotor_inertia", "payload",
                     "gravity_compensator", "sensor_delay", "backlash", "joint_flexibility")
IN_LIBRARY_FREQ = ("joint_flexibility", "orthogonal_compliance", "link_flexibility", "hysteretic_damping",
                   "fractional_damping", "payload")
OUT_OF_LIBRARY = {"torque": ("cogging", "gain_drift", "torque_deadzone"), "frf": ("rocking_base", "posture_bearing"),
                  "modal": ("rocking_base", "posture_bearing")}
JOINTLESS = ("payload", "sensor_delay", "gain_drift", "rocking_base")


def family(effects) -> str:
    if not effects:
        return "null"
    if any(e in sum(OUT_OF_LIBRARY.values(), ()) for e in effects):
        return "out_of_library"
    return "single" if len(effects) == 1 else "pair"


def _write(folder, model_nom, tool, name, nominal, datasets, truth, noise=None):
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "robot.urdf").write_text(R.urdf_text(model_nom, tool, name))
    ds = []
    for kind, fname, split, arrays in datasets:
        np.savez(folder / f"{fname}.npz", **arrays)
        ds.append(dict(kind=kind, file=f"{fname}.npz", split=split))
    cfg = dict(robot="robot.urdf", tool_frame=tool, nominal_effects=nominal, datasets=ds)
    if noise:
        cfg["noise"] = noise
    (folder / "case.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    (folder / "truth.json").write_text(json.dumps(truth, indent=1))
    return folder


def _amp(model, home, amp):
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    return np.minimum(amp, 0.9 * np.minimum(home - lo, hi - home))


def _jn(model, j):
    return None if j is None else model.names[j + 1]


# --- torque cases ---------------------------------------------------------------------------------
def torque_case(folder, robot, effects, seed, small=False):
    rng = np.random.default_rng(seed)
    true, tool, home = R.true_model(robot)
    nom, cad = R.cad_error(true, rng)
    n = true.nq
    fs = float(rng.choice([200.0, 250.0, 500.0, 1000.0]))
    step = 2 * np.pi / 2 ** int(rng.integers(18, 21))
    noise_pct = rng.uniform(0.5, 2.0)
    pole = rng.uniform(0.6, 0.9)
    T = 3.0 if small else 5.0
    t = np.arange(int(round(T * fs))) / fs
    amp = _amp(true, home, 0.7 if robot == "arm3" else 0.5)
    trajs = [S.Fourier(rng, home + rng.uniform(-0.15, 0.15, n) * (amp > 0.3), amp, f0=1.0 / T) for _ in range(3)]
    q, qd, qdd = trajs[0](t), trajs[0](t, 1), trajs[0](t, 2)
    scale = TQ.rnea_batch(true, q, qd, qdd).std(axis=0)
    Fv = rng.uniform(0.03, 0.08, n) * scale / qd.std(axis=0)
    Fc = rng.uniform(0.03, 0.08, n) * scale
    data = true.createData()
    Mh = np.diag(pin.crba(true, data, home))
    drawn, truth_eff, used = [], [], set()
    sensor = {}
    for eff in effects:
        r = rng.uniform(0.08, 0.15)
        if eff in JOINTLESS:
            j = None
        elif eff == "gravity_compensator":
            j = 1  # the shoulder, the joint gravity loads most
        elif eff == "backlash":
            # a joint whose torque reverses often (a vertical axis or a wrist), where play shows
            tq = TQ.rnea_batch(true, q, qd, qdd)
            crossings = (np.diff(np.sign(tq), axis=0) != 0).sum(axis=0)
            j = int(np.argmax(crossings + 1e-3 * rng.random(n)))
        elif eff == "joint_flexibility":
            j = int(rng.integers(1, min(n, 3)))  # a gravity-loaded joint: its deflection shows in the torques
        else:
            j = int(rng.choice([k for k in range(n) if k not in used]))
        used.add(j)
        s = scale[j] if j is not None else None
        if eff == "viscous_friction":
            p = {"Fv": float(r * s / qd[:, j].std())}
            Fv[j] = 0.0
        elif eff == "coulomb_friction":
            p = {"Fc": float(r * s)}
            Fc[j] = 0.0
        elif eff == "stribeck_friction":
            p = {"Fc": float(Fc[j]), "Fs": float(Fc[j] + rng.uniform(0.2, 0.35) * s), "vs": float(rng.uniform(0.03, 0.1))}
        elif eff == "rotor_inertia":
            p = {"Ia": float(r * s / qdd[:, j].std())}
        elif eff == "gravity_compensator":
            g = TQ.gravity_batch(true, q)[:, j]
            base = dict(k=1.0, a=0.35, r=0.12, l0=0.05)
            phis = np.linspace(-np.pi, np.pi, 16, endpoint=False)
            cor = [np.corrcoef(TQ.compensator_torque(q[:, j], phi0=ph, **base), g)[0, 1] for ph in phis]
            ph = float(phis[int(np.argmin(cor))])
            unit = TQ.compensator_torque(q[:, j], phi0=ph, **base)
            p = dict(base, phi0=ph, k=float(rng.uniform(0.1, 0.2) * np.abs(g).mean() / np.sqrt(np.mean(unit**2))))
        elif eff == "payload":
            p = {"m": float(rng.uniform(0.5, 1.5) if robot == "panda" else rng.uniform(1.0, 3.0)),
                 "offset": [float(v) for v in rng.uniform(-0.03, 0.03, 3) + [0, 0, 0.05]], "radius": 0.04}
        elif eff == "sensor_delay":
            p = {"d": float(rng.uniform(0.006, 0.02))}
            sensor["delay"] = p["d"]
        elif eff == "backlash":
            k = (2 * np.pi * rng.uniform(25, 40)) ** 2 * Mh[j]
            p = {"b": float(rng.uniform(0.004, 0.012)), "k": float(k), "c": float(2 * 0.1 * np.sqrt(k * Mh[j]))}
        elif eff == "joint_flexibility":
            k = (2 * np.pi * rng.uniform(4, 7)) ** 2 * Mh[j]
            p = {"k": float(k), "c": float(2 * 0.05 * np.sqrt(k * Mh[j]))}
        elif eff == "cogging":
            p = {"A": float(r * s), "periods": float(rng.uniform(15, 30)), "phase": float(rng.uniform(0, 2 * np.pi))}
        elif eff == "gain_drift":
            j = int(rng.integers(0, n))
            p = {"train_offset": [0.0, float(rng.uniform(0.0, 0.02))], "validation_offset": float(rng.uniform(0.05, 0.08)),
                 "ramp": float(rng.uniform(0.02, 0.05))}
            sensor["gain"] = (j, p)
        elif eff == "torque_deadzone":
            p = {"width": float(rng.uniform(0.1, 0.2) * s)}
            sensor["deadzone"] = (j, p["width"])
        else:
            raise KeyError(f"unknown torque effect {eff!r}")
        if eff not in ("sensor_delay", "gain_drift", "torque_deadzone"):
            drawn.append((eff, j, p))
        truth_eff.append(dict(effect=eff, joint=_jn(true, j), params=p,
                              in_library=eff not in OUT_OF_LIBRARY["torque"]))
    # a sub-sample lag between the angle and torque channels, unknown to the user, in some cases
    nuisance = float(rng.uniform(0.2, 1.0) / fs) if (effects and "sensor_delay" not in effects and rng.random() < 0.4) else 0.0
    delay = sensor.get("delay", 0.0) + nuisance
    datasets = []
    for i, tr in enumerate(trajs):
        split = "train" if i < 2 else "validation"
        tau = TQ.true_torque(true, tool, tr, drawn, (Fv, Fc), t - delay)
        if "gain" in sensor:
            j, p = sensor["gain"]
            off = p["train_offset"][i] if split == "train" else p["validation_offset"]
            tau[:, j] *= 1.0 + off + p["ramp"] * t / t[-1]
        if "deadzone" in sensor:
            j, w = sensor["deadzone"]
            tau[:, j] = np.sign(tau[:, j]) * np.maximum(np.abs(tau[:, j]) - w, 0.0)
        tau = tau + S.ar1_noise(rng, tau.shape, pole, noise_pct / 100 * tau.std(axis=0))
        datasets.append(("torque", f"traj{i}", split, dict(t=t, q=S.quantise(tr(t), step), tau=tau)))
    laws = {"viscous_friction": Fv, "coulomb_friction": Fc}
    nominal = []
    for law, vals in laws.items():
        js = [true.names[k + 1] for k in range(n) if vals[k] > 0]
        if js:
            nominal.append(dict(effect=law, joint="all" if len(js) == n else js))
    truth = dict(kind="torque", robot=robot, family=family(effects), effects=truth_eff,
                 expected_verdict=_expected(effects),
                 realism=dict(fs_hz=fs, encoder_step_rad=step, noise_pct=noise_pct, noise_ar1_pole=pole,
                              nuisance_delay_s=nuisance, friction_Fv=Fv.tolist(), friction_Fc=Fc.tolist(),
                              torque_std=scale.tolist()),
                 cad_error=cad)
    return _write(folder, nom, tool, robot, nominal, datasets, truth)


def _expected(effects):
    fam = family(effects)
    return {"null": "within_noise", "out_of_library": "unexplained"}.get(fam, "explained")


# --- frequency cases ------------------------------------------------------------------------------
def freq_case(folder, kind, robot, effects, seed, small=False):
    rng = np.random.default_rng(seed)
    true, tool, home = R.true_model(robot)
    nom, cad = R.cad_error(true, rng)
    n = true.nq
    data = true.createData()
    Mh = np.diag(pin.crba(true, data, home))
    fj = np.sort(rng.uniform(8.0, 30.0, n))[::-1] if robot != "arm3" else np.array(
        [rng.uniform(8, 14), rng.uniform(12, 20), rng.uniform(18, 30)])
    joint = []
    for i in range(n):
        k = (2 * np.pi * fj[i]) ** 2 * Mh[i]
        B = rng.uniform(0.3, 1.0) * Mh[i]
        kp = rng.uniform(20, 40) * k
        joint.append(dict(k=float(k), c=float(2 * rng.uniform(0.02, 0.05) * np.sqrt(k * Mh[i])), law="viscous",
                          B=float(B), kp=float(kp), kd=float(2 * 0.7 * np.sqrt(kp * B))))
    f_lo, f_hi = max(2.0, 0.5 * fj.min()), 1.6 * fj.max()
    aug = dict(orth=(), bend=(), rocking=None, bend_at=0.5)
    vK, vC, truth_eff, payload, bearing = [], [], [], None, None
    rigid_nominal = None
    for eff in effects:
        j = None
        if eff == "joint_flexibility":
            j = int(rng.integers(0, n))
            rigid_nominal = j
            p = {"k": joint[j]["k"], "c": joint[j]["c"]}
        elif eff == "hysteretic_damping":
            j = int(rng.integers(0, n))
            joint[j].update(law="hysteretic", eta=float(rng.uniform(0.04, 0.08)))
            p = {"eta": joint[j]["eta"]}
        elif eff == "fractional_damping":
            j = int(rng.integers(0, n))
            al = float(rng.uniform(0.3, 0.7))
            w = 2 * np.pi * fj[j]
            c = 2 * joint[j]["c"] * w / (w**al * np.sin(al * np.pi / 2))
            joint[j].update(law="fractional", alpha=al, c=float(c))
            p = {"alpha": al, "c": float(c)}
        elif eff in ("orthogonal_compliance", "link_flexibility"):
            if eff == "orthogonal_compliance":
                j = int(rng.integers(1, n))
                aug["orth"] = (j,)
            else:
                j = int(rng.integers(1, n - 1)) if n > 2 else 0
                aug["bend"] = (j,)
                aug["bend_at"] = float(rng.uniform(0.35, 0.65))
            p = {"f_target_hz": [float(v) for v in rng.uniform(0.4, 0.9, 2) * f_hi], "coupling": 0.3}
            if eff == "link_flexibility":
                p["hinge_at"] = aug["bend_at"]
        elif eff == "rocking_base":
            aug["rocking"] = pin.Inertia(40.0, np.array([0.0, 0.0, -0.2]), np.diag([2.0, 2.0, 1.0]))
            p = {"f_target_hz": float(rng.uniform(0.35, 0.7) * f_hi), "base_mass": 40.0}
        elif eff == "payload":
            p = {"m": float(rng.uniform(0.5, 1.5) if robot == "panda" else rng.uniform(1.0, 3.0)),
                 "offset": [float(v) for v in rng.uniform(-0.03, 0.03, 3) + [0, 0, 0.05]], "radius": 0.04}
            payload = p
        elif eff == "posture_bearing":
            j = int(rng.integers(0, n))
            p = {"k0": joint[j]["k"], "depth": 0.45, "law": "k0 * (1 + depth * cos(2 q[0]))"}
            bearing = (j, p)
        else:
            raise KeyError(f"unknown frequency-side effect {eff!r}")
        truth_eff.append(dict(effect=eff, joint=_jn(true, j) if eff != "link_flexibility" else None,
                              link=R.link_names(true)[j + 1] if eff == "link_flexibility" else None, params=p,
                              in_library=eff not in OUT_OF_LIBRARY["frf"]))
    phys = R.add_payload(true, tool, payload["m"], payload["offset"], payload["radius"]) if payload else true
    model, fid, act, virt = F.augment(phys, tool, orth=aug["orth"], bend=aug["bend"], rocking=aug["rocking"], bend_at=aug["bend_at"])
    if virt:
        # springs of the virtual coordinates set from their mass at the home posture (target frequencies)
        qh = np.zeros(model.nq)
        qh[act] = home
        Mv = pin.crba(model, model.createData(), qh)
        Mv = np.triu(Mv) + np.triu(Mv, 1).T
        tv = [e for e in truth_eff if e["effect"] in ("orthogonal_compliance", "link_flexibility", "rocking_base")][0]["params"]
        ft = np.atleast_1d(tv["f_target_hz"])
        kd = np.array([(2 * np.pi * ft[i]) ** 2 * Mv[v, v] for i, v in enumerate(virt)])
        K = np.diag(kd)
        if len(virt) == 2:
            K[0, 1] = K[1, 0] = 0.3 * np.sqrt(kd[0] * kd[1])
        C = np.diag(2 * 0.03 * np.sqrt(kd * np.array([Mv[v, v] for v in virt])))
        vK, vC = K, C
        tv["stiffness"] = K.tolist()
    n_post = 4 if kind == "modal" else 3
    postures = []
    lo, hi = true.lowerPositionLimit, true.upperPositionLimit
    spread = np.linspace(-0.6, 0.6, n_post)
    rng.shuffle(spread)
    for s in range(n_post):
        qp = home + rng.uniform(-0.35, 0.35, n)
        qp[0] = home[0] + spread[s]  # the base angle differs between postures
        postures.append(np.clip(qp, lo + 0.05, hi - 0.05))
    nlines = 150 if small else 250
    datasets = []
    fs = float(2 ** np.ceil(np.log2(4 * f_hi)))
    nper = 2048 if small else 4096
    nsamp = 2**16 if small else 2**18
    in_noise, out_noise = rng.uniform(0.01, 0.03), rng.uniform(0.02, 0.05)
    modal_pct = rng.uniform(0.5, 1.0)
    for s, q0 in enumerate(postures):
        split = "train" if s < n_post - 1 else "validation"
        js = [dict(d) for d in joint]
        if bearing is not None:
            j, p = bearing
            js[j]["k"] = p["k0"] * (1 + p["depth"] * np.cos(2 * q0[0]))
        lin = F.Linear(model, fid, act, virt, q0, js, (vK, vC) if virt else None)
        if kind == "frf":
            f, H1 = S.h1_frf(lin.frf, fs, nsamp, nper, rng, in_noise, out_noise)
            band = np.flatnonzero((f >= f_lo) & (f <= f_hi))
            pick = np.unique(np.searchsorted(f[band], np.geomspace(f_lo, f_hi, nlines)).clip(0, band.size - 1))
            sel = band[pick]
            datasets.append(("frf", f"frf_p{s}", split, dict(q0=q0, freq=f[sel], H=H1[:, sel].mean(axis=0), H_repeats=H1[:, sel])))
        else:
            fn, z = lin.modes()
            keep = fn <= f_hi
            fn, z = fn[keep], z[keep]
            fn = fn * (1 + modal_pct / 100 * rng.standard_normal(fn.size))
            z = z * (1 + 0.15 * rng.standard_normal(z.size))
            o = np.argsort(fn)
            datasets.append(("modal", f"modes_p{s}", split, dict(q0=q0, freq=fn[o], zeta=np.clip(z[o], 1e-4, 0.9))))
    flex = [i for i in range(n) if i != rigid_nominal]
    nominal = [dict(effect="joint_flexibility", joint=[true.names[i + 1] for i in flex],
                    stiffness=[float(joint[i]["k"] * (1 + rng.choice([-1, 1]) * rng.uniform(0.3, 0.5))) for i in flex],
                    damping=[float(joint[i]["c"] * rng.uniform(0.5, 2.0)) for i in flex])]
    truth = dict(kind=kind, robot=robot, family=family(effects), effects=truth_eff, expected_verdict=_expected(effects),
                 realism=dict(joint=joint, band_hz=[f_lo, f_hi], h1_fs_hz=fs, h1_nperseg=nper, h1_samples=nsamp,
                              input_noise=in_noise, output_noise=out_noise, modal_frequency_noise_pct=modal_pct),
                 cad_error=cad)
    noise = {"modal_frequency_pct": 1.0} if kind == "modal" else None
    return _write(folder, nom, tool, robot, nominal, datasets, truth, noise)


# --- tip cases --------------------------------------------------------------------------------------
def tip_case(folder, robot, effects, seed, small=False, cad_error=False):
    """Tool positions only (a tracker's view) under applied torques, from rest at a drawn posture:
    two training records and one validation record, 1 s each at 200 Hz, 0.1 mm white noise; the
    rotor inertias stated as nominal values. ``effects``: () or ("joint_flexibility",): a spring
    at a drawn joint whose mode lies at 4-12 Hz; ("joint_flexibility", "backlash"): that spring
    with play of half-width 15-40 mrad inside it (a sharp dead zone, :func:`.tip.dead_zone`; the
    applied torques reverse at every joint along these motions, so the play shows; the springs
    are soft, 0.1-0.4 rad of deflection along them, and a play of a few mrad is lost in that). ``cad_error``:
    the case's robot a few per cent off (tip records alone cannot identify the inertias; off by
    default)."""
    rng = np.random.default_rng(seed)
    true, tool, home = R.true_model(robot)
    nom, cad = R.cad_error(true, rng) if cad_error else (true, [])
    n = true.nq
    data = true.createData()
    Mh = np.diag(pin.crba(true, data, home))
    rotor = Mh * rng.uniform(0.15, 0.3, n)
    flex, truth_eff = None, []
    if "backlash" in effects and "joint_flexibility" not in effects:
        raise KeyError("tip cases plant backlash inside a spring: effects ('joint_flexibility', 'backlash')")
    for eff in effects:
        if eff == "backlash":  # play inside the spring drawn before it (same joint)
            j = flex[0]
            b = float(rng.uniform(0.015, 0.04))
            flex = flex + (b,)
            truth_eff.append(dict(effect=eff, joint=_jn(true, j), params={"b": b}, in_library=True))
            continue
        if eff != "joint_flexibility":
            raise KeyError(f"tip cases plant joint_flexibility (and backlash inside it) only, got {eff!r}")
        j = int(rng.integers(0, n))
        f = rng.uniform(4.0, 12.0)  # [Hz] the motor's mode on its spring
        k = float((2 * np.pi * f) ** 2 * rotor[j])
        c = float(2 * rng.uniform(0.03, 0.1) * np.sqrt(k * rotor[j]))
        flex = (j, k, c)
        truth_eff.append(dict(effect=eff, joint=_jn(true, j), params={"k": k, "c": c, "rotor_inertia": float(rotor[j])},
                              in_library=True))
    fs, T = 200.0, 0.6 if small else 1.0
    amp = _amp(true, home, 0.25)
    datasets = []
    for i, split in enumerate(["train", "train", "validation"]):
        q0 = home + rng.uniform(-0.4, 0.4, n) * (amp > 0.1)
        t, q, qd, qdd = TP.rest_motion(rng, q0, T, fs, amp=amp)
        tau = TP.applied_torques(true, rotor, q, qd, qdd)
        y = TP.simulate_tip(true, tool, rotor, t, tau, q0, flex) + 1e-4 * rng.standard_normal((t.size, 3))
        datasets.append(("response", f"tip{i}", split, dict(t=t, tau=tau, y=y, channels=np.array(["tip_x", "tip_y", "tip_z"]),
                                                            q0=q0)))
    nominal = [dict(effect="rotor_inertia", joint="all", value=[float(v) for v in rotor])]
    truth = dict(kind="tip", robot=robot, family=family(effects), effects=truth_eff, expected_verdict=_expected(effects),
                 cad_error=cad)
    return _write(folder, nom, tool, robot, nominal, datasets, truth)


def make_case(folder, kind="torque", robot="arm3", effects=(), seed=0, small=False) -> tuple[pathlib.Path, dict]:
    """Write one case folder (``case.yaml``, ``robot.urdf``, NPZ files, ``truth.json``).

    **Arguments:** ``folder``; ``kind``: torque | frf | modal | tip; ``robot``: arm3 | ur5 | panda;
    ``effects``: hidden effect names (library names, or out-of-library ``cogging``,
    ``gain_drift``, ``torque_deadzone`` for torque data, ``rocking_base``, ``posture_bearing`` for
    frf/modal data; empty: a null case); ``seed``; ``small``: short records (3 s torque records,
    a shorter FRF test) for tests.

    **Returns:** ``(folder, truth)``, the truth as written to ``folder/truth.json``.
    """
    effects = tuple(effects)
    if kind == "torque":
        out = torque_case(folder, robot, effects, seed, small)
    elif kind == "tip":
        out = tip_case(folder, robot, effects, seed, small)
    elif kind in ("frf", "modal"):
        out = freq_case(folder, kind, robot, effects, seed, small)
    else:
        raise ValueError(f"kind: expected torque, frf, modal or tip, got {kind!r}")
    return out, json.loads((out / "truth.json").read_text())


# --- the bench's list of cases --------------------------------------------------------------------
def plan(size: str = "small") -> list[dict]:
    """Cases of the bench: ``id``, ``kind``, ``robot``, ``effects``, ``seed``. ``small``: 11 cases,
    every family (single, pair, out-of-library, null) and data kind; ``full``: 39 (36-37 tip
    records only: a flexible joint and a null case; 38, appended last so the others keep their
    ids: tip records of a flexible joint with backlash inside its transmission)."""
    S_ = [("torque", "arm3", ("stribeck_friction",)), ("torque", "ur5", ("payload",)),
          ("torque", "arm3", ("joint_flexibility",)), ("frf", "arm3", ("orthogonal_compliance",)),
          ("modal", "arm3", ("payload",)), ("torque", "panda", ("coulomb_friction", "sensor_delay")),
          ("torque", "arm3", ("cogging",)), ("frf", "arm3", ("rocking_base",)),
          ("torque", "panda", ()), ("frf", "arm3", ()), ("modal", "arm3", ())]
    if size == "full":
        robots = ("arm3", "ur5", "panda")
        S_ = [("torque", robots[i % 3], (e,)) for i, e in enumerate(IN_LIBRARY_TORQUE)]
        S_ += [("frf", "arm3", (e,)) for e in IN_LIBRARY_FREQ]
        S_ += [("frf", "ur5", ("joint_flexibility",)), ("frf", "ur5", ("orthogonal_compliance",)),
               ("modal", "arm3", ("joint_flexibility",)), ("modal", "arm3", ("payload",))]
        S_ += [("torque", "arm3", ("coulomb_friction", "payload")), ("torque", "ur5", ("viscous_friction", "backlash")),
               ("torque", "panda", ("rotor_inertia", "gravity_compensator")), ("torque", "arm3", ("stribeck_friction", "sensor_delay")),
               ("frf", "arm3", ("hysteretic_damping", "orthogonal_compliance"))]
        S_ += [("torque", "arm3", ("cogging",)), ("torque", "ur5", ("gain_drift",)), ("torque", "panda", ("torque_deadzone",)),
               ("frf", "arm3", ("rocking_base",)), ("frf", "arm3", ("posture_bearing",)), ("modal", "arm3", ("posture_bearing",))]
        S_ += [("torque", r, ()) for r in robots] + [("frf", "arm3", ()), ("frf", "ur5", ()), ("modal", "arm3", ())]
        # tool positions only: a flexible joint only a simulation shows, and a null case
        S_ += [("tip", "arm3", ("joint_flexibility",)), ("tip", "arm3", ())]
        # backlash inside the compliant transmission: a candidate only a simulation shows too
        S_ += [("tip", "arm3", ("joint_flexibility", "backlash"))]
    out = []
    for i, (kind, robot, eff) in enumerate(S_):
        out.append(dict(id=f"{i:02d}_{kind}_{robot}_{'+'.join(eff) or 'null'}", kind=kind, robot=robot, effects=list(eff),
                        seed=7000 + 17 * i + (0 if size == "small" else 1000), family=family(eff)))
    return out
