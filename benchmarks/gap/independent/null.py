"""The null family of the gap bench: cases where nothing is missing from the nominal model, made by
independent code (Pinocchio, SciPy, NumPy; nothing from jflex), to measure how often the diagnosis
raises a false alarm.

The true robot differs from the case's URDF only by CAD errors (every link's mass 2-10 % off, its
centre of mass 0.5-2 cm off); its every-joint friction (viscous + Coulomb) is stated in case.yaml's
nominal model, whose coefficients the diagnosis refits. What varies is how the records were logged,
combined per case (``TRAITS``, one value each):

``noise``       ``white`` (0.5-2 % of the joint's torque std) or ``ar1`` coloured noise (1-3 %, pole 0.6-0.9)
``angles``      ``fine`` (a 2^19-count encoder, angles only) or ``encoder`` (2^16-2^18 counts per
                revolution, logged velocities from backward differences of the counts, 1 kHz)
``torque``      ``float``, ``adc12`` (torques through a 12-bit converter) or ``current12`` (motor
                currents through a 12-bit converter in a CSV; case.yaml states the exact
                current-to-torque scale and the current offsets)
``hum``         50 Hz mains hum on every torque channel (0.5-1.5 % of its torque std) or none
``stamps``      ``uniform`` or ``jitter`` (a CSV whose stamps jitter by 20 % of the step, with dropped
                samples, repeated and stale rows: reallog's :func:`jittered_stamps`)
``clip``        one channel's logged values clipped at a limit set per run, for 1-4 % of its samples (a
                sensor's or logger's range: the robot got the full torque)
``loop``        ``open`` (the robot follows the reference) or ``closed`` (reallog's PID with CAD
                feed-forward: the logged torque is the command, the logged angles the plant's)
``excitation``  ``aperiodic`` (a Fourier series whose period exceeds the record) or ``periodic``
                (three periods of one)

:func:`plan` lists the cases, :func:`make_null_case` writes one folder: ``case.yaml``,
``robot.urdf`` (the CAD robot), the records (NPZ, or CSV where a trait is about the file) and
``truth.json`` (``effects`` empty, ``family`` ``null``, the traits as drawn) for the scorer only.
"""

from __future__ import annotations

import json
import pathlib

import numpy as np
import pinocchio as pin

from . import reallog as RL
from . import robots as R
from . import signals as S

ROBOTS = ("arm3", "planar2", "ur5", "panda", "z1")
TRAITS = dict(noise=("white", "ar1"), angles=("fine", "encoder"), torque=("float", "adc12", "current12"),
              hum=(False, True), stamps=("uniform", "jitter"), clip=(False, True), loop=("open", "closed"),
              excitation=("aperiodic", "periodic"))
PLAIN = {k: v[0] for k, v in TRAITS.items()}
ADC_CODES = 2047       # a 12-bit signed converter: codes -2047..2047 (symmetric full scale)
ADC_HEADROOM = 1.2     # full scale over the largest value of an unclipped channel
HUM_HZ = 50.0
CLIP_SHARE = (0.01, 0.04)
PERIODS = 3

PLANAR2_URDF = """<?xml version="1.0"?>
<robot name="planar2">
  <link name="base_link"/>
  <joint name="shoulder" type="revolute">
    <parent link="base_link"/><child link="upper"/>
    <origin xyz="0 0 0.50" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2.8" upper="2.8" effort="200" velocity="3"/>
  </joint>
  <link name="upper">
    <inertial><origin xyz="0.22 0 0.01" rpy="0 0 0"/><mass value="6.0"/>
      <inertia ixx="0.012" ixy="0" ixz="0" iyy="0.11" iyz="0" izz="0.105"/></inertial>
  </link>
  <joint name="elbow" type="revolute">
    <parent link="upper"/><child link="fore"/>
    <origin xyz="0.50 0.06 0" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2.6" upper="2.6" effort="100" velocity="3"/>
  </joint>
  <link name="fore">
    <inertial><origin xyz="0.18 0 0" rpy="0 0 0"/><mass value="3.2"/>
      <inertia ixx="0.005" ixy="0" ixz="0" iyy="0.045" iyz="0" izz="0.043"/></inertial>
  </link>
  <joint name="tool_joint" type="fixed">
    <parent link="fore"/><child link="tool"/><origin xyz="0.40 0 0" rpy="0 0 0"/>
  </joint>
  <link name="tool"/>
</robot>
"""
# Unitree Z1 from example-robot-data, its gripper locked closed
Z1 = ("z1_description/urdf/z1.urdf", "gripperMover", [0.0, 1.2, -1.0, -0.2, 0.0, 0.0], ("jointGripper",))


def true_model(name: str) -> tuple[pin.Model, str, np.ndarray]:
    """The true robot ``name`` (:data:`ROBOTS`): Pinocchio model, tool frame, home posture [rad]."""
    if name == "planar2":
        return pin.buildModelFromXML(PLANAR2_URDF), "tool", np.array([0.4, 0.9])
    if name == "z1":
        rel, tool, home, lock = Z1
        model = pin.buildModelFromUrdf(str(R.erd_root() / rel))
        model = pin.buildReducedModel(model, [model.getJointId(j) for j in lock], pin.neutral(model))
        return model, tool, np.array(home)
    return R.true_model(name)


def plan(size: str = "small") -> list[dict]:
    """The family's cases: ``id``, ``robot``, ``seed``, ``traits``. ``full``: one plain case per
    robot (white noise, fine angles, uniform stamps, open loop: the baseline) and 30 with traits
    drawn balanced (each value of each trait in an equal share of them, shuffled apart), the robots
    in turn; ``small``: six of those shapes on the light robots (arm3, planar2)."""
    if size not in ("small", "full"):
        raise ValueError(f"size: expected 'small' or 'full', got {size!r}")
    n_mixed = 30 if size == "full" else 5
    robots = ROBOTS if size == "full" else ("arm3", "planar2")
    rng = np.random.default_rng(4242)
    cols = {}
    for k, vals in TRAITS.items():
        a = np.resize(np.arange(len(vals)), n_mixed)
        rng.shuffle(a)
        cols[k] = [vals[i] for i in a]
    shapes = [(r, dict(PLAIN)) for r in (robots if size == "full" else robots[:1])]
    shapes += [(robots[i % len(robots)], {k: cols[k][i] for k in TRAITS}) for i in range(n_mixed)]
    out = []
    for i, (robot, tr) in enumerate(shapes):
        out.append(dict(id=f"n{i:02d}_{robot}_{code(tr)}", robot=robot, seed=7300 + 17 * i + (0 if size == "full" else 500),
                        traits=tr))
    return out


def code(tr: dict) -> str:
    """A short name of a trait combination (``plain`` when it is :data:`PLAIN`)."""
    parts = [tr["noise"] if tr["noise"] != "white" else "",
             "enc" if tr["angles"] == "encoder" else "", {"float": "", "adc12": "adc", "current12": "cur"}[tr["torque"]],
             "hum" if tr["hum"] else "", "jit" if tr["stamps"] == "jitter" else "", "clip" if tr["clip"] else "",
             "cl" if tr["loop"] == "closed" else "", "per" if tr["excitation"] == "periodic" else ""]
    return "-".join(p for p in parts if p) or "plain"


def _adc(x, full_scale):
    """``x`` through a signed converter of ``ADC_CODES`` codes either side of zero over
    ``+-full_scale`` (values beyond it read the end code)."""
    step = full_scale / ADC_CODES
    return np.clip(np.round(x / step), -ADC_CODES, ADC_CODES) * step, step


def make_null_case(folder, spec: dict) -> tuple[pathlib.Path, dict]:
    """Write the case folder of ``spec`` (a :func:`plan` entry: ``robot``, ``seed``, ``traits``, the
    missing traits :data:`PLAIN`). Returns ``(folder, truth)``."""
    tr = dict(PLAIN, **spec.get("traits", {}))
    for k, v in tr.items():
        if k not in TRAITS or v not in TRAITS[k]:
            raise ValueError(f"traits.{k}: expected one of {TRAITS.get(k)}, got {v!r}")
    robot = spec["robot"]
    rng = np.random.default_rng(spec["seed"])
    srng = np.random.default_rng(spec["seed"] + 10_000)  # stamps and log rows: the physics' draws apart
    true, tool, home = true_model(robot)
    cad, caderr = R.cad_error(true, rng)
    n = true.nq
    names = [true.names[m + 1] for m in range(n)]
    encoder = tr["angles"] == "encoder"
    fs = 1000.0 if encoder else 500.0  # a 1 kHz loop keeps the backward difference's half-step lag small
    if tr["excitation"] == "periodic":
        P = 1.2 if encoder else 1.6
        T, f0, harmonics = PERIODS * P, 1.0 / P, 4
    else:
        P, T, harmonics = None, (3.0 if encoder else 5.0), 5
        f0 = 1.0 / (1.37 * T)  # the series' period outlasts the record: no repeat within it
    lo, hi = true.lowerPositionLimit, true.upperPositionLimit
    amp = np.minimum(0.6 if n <= 3 else 0.45, 0.9 * np.minimum(home - lo, hi - home))
    trajs = [S.Fourier(rng, home + rng.uniform(-0.1, 0.1, n), amp, f0=f0, harmonics=harmonics) for _ in range(3)]
    Fv, Fc, scale, qdstd = RL._friction(rng, true, trajs[0], T)
    if tr["noise"] == "white":
        noise_pct, pole = rng.uniform(0.5, 2.0, n), 0.0
    else:
        noise_pct, pole = rng.uniform(1.0, 3.0, n), float(rng.uniform(0.6, 0.9))
    noise_std = noise_pct / 100 * scale
    hum_amp = (rng.uniform(0.5, 1.5, n) / 100 * scale) if tr["hum"] else np.zeros(n)
    counts = int(2 ** rng.integers(16, 19)) if encoder else 2**19
    q_step = 2 * np.pi / counts
    jc = int(rng.integers(n)) if tr["clip"] else None
    share = float(rng.uniform(*CLIP_SHARE)) if tr["clip"] else 0.0
    currents = tr["torque"] == "current12"
    if currents:
        gear = rng.choice([50.0, 80.0, 100.0, 120.0, 160.0], n)
        k_t = rng.uniform(0.05, 0.2, n)
        i0 = rng.uniform(-0.05, 0.05, n)
        K = np.diag(gear)

    recs, tracking, stamps = [], [], []
    for i, traj in enumerate(trajs):
        if tr["stamps"] == "jitter":
            t, rows = RL.jittered_stamps(srng, T + (1.0 / fs if encoder else 0.0), fs)
        else:
            t, rows = np.arange(int(round(T * fs)) + (1 if encoder else 0)) / fs, None
        if tr["loop"] == "closed":
            q, qd, qdd, tau, ref = RL.closed_loop(true, cad, traj, home, t, (Fv, Fc), [])
            tracking.append(np.abs(q - ref).max(axis=0).tolist())
        else:
            q, qd, qdd, tau = RL.open_loop(true, traj, t, (Fv, Fc), [])
        e = (rng.standard_normal(tau.shape) * noise_std[None] if pole == 0.0
             else S.ar1_noise(rng, tau.shape, pole, noise_std))
        phase = rng.uniform(0, 2 * np.pi, n)
        x = tau + e + hum_amp[None] * np.sin(2 * np.pi * HUM_HZ * t[:, None] + phase[None])
        qm = S.quantise(q, q_step)
        rec = dict(t=t, q=qm, x=x, rows=rows)
        if encoder:
            # the controller differentiates its counts over its own sample times; the first sample
            # has no predecessor and is not logged
            rec.update(t=t[1:], q=qm[1:], x=x[1:], qd=np.diff(qm, axis=0) / np.diff(t)[:, None])
            if rows is not None:
                rec["rows"] = rows[rows > 0] - 1
        if currents:
            rec["x"] = RL.current_from_torque(K, k_t, rec["x"], i0)
        recs.append(rec)

    # the clipped channel's range is set per run, at the share of that run's samples it cuts (only the
    # log is clipped); the converter's end code is that limit, elsewhere one full scale per channel
    # over the session
    allx = np.concatenate([r["x"] for r in recs])
    fsc = ADC_HEADROOM * np.abs(allx).max(axis=0)
    limits, adc_step = [], None
    for rec in recs:
        if jc is not None:
            lim = float(np.quantile(np.abs(rec["x"][:, jc]), 1.0 - share))
            rec["x"][:, jc] = np.clip(rec["x"][:, jc], -lim, lim)
            fsc[jc] = lim
            limits.append(lim)
        if tr["torque"] in ("adc12", "current12"):
            cols = [_adc(rec["x"][:, m], fsc[m]) for m in range(n)]
            rec["x"] = np.stack([c[0] for c in cols], axis=1)
            adc_step = [float(c[1]) for c in cols]  # the last run's (the clipped channel's differs per run)

    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    csv = tr["stamps"] == "jitter" or currents
    ds, clip_share = [], []
    for i, rec in enumerate(recs):
        t, qm, x, qd = rec["t"], rec["q"], rec["x"], rec.get("qd")
        if rec["rows"] is not None:
            # stale rows repeat the last fresh reading at their own stamp, in order (a run of them
            # holds it); then rows logged twice (as reallog's jittered log)
            stale = np.flatnonzero(srng.random(t.size) < RL.STALE_FRACTION)
            stale = stale[stale > 0]
            for k in stale:
                qm[k], x[k] = qm[k - 1], x[k - 1]
                if qd is not None:
                    qd[k] = qd[k - 1]
            rows = rec["rows"]
            t, qm, x = t[rows], qm[rows], x[rows]
            qd = None if qd is None else qd[rows]
            dt = np.diff(t)
            stamps.append(dict(rows=int(t.size), repeated_rows=int(np.sum(dt == 0)), stale_rows=int(stale.size),
                               max_step_over_nominal=float(dt.max() * fs)))
        if jc is not None:
            clip_share.append(float(np.mean(np.abs(x[:, jc]) >= np.abs(x[:, jc]).max() * (1 - 1e-9))))
        name, split = f"traj{i}", "train" if i < 2 else "validation"
        if not csv:
            arrays = dict(t=t, q=qm, tau=x)
            if qd is not None:
                arrays["qd"] = qd
            np.savez(folder / f"{name}.npz", **arrays)
            ds.append(dict(kind="torque", file=f"{name}.npz", split=split))
            continue
        vcols = [f"{m}_vel" for m in names] if qd is not None else []
        tcols = [f"motor{m + 1}_current" for m in range(n)] if currents else [f"{m}_effort" for m in names]
        RL._write_csv(folder / f"{name}.csv", ["time"] + [f"{m}_pos" for m in names] + vcols + tcols,
                      [t, *qm.T, *([] if qd is None else qd.T), *x.T])
        cmap = dict(time="time", position={m: f"{m}_pos" for m in names})
        if qd is not None:
            cmap["velocity"] = dict(zip(names, vcols))
        cmap["torque"] = dict(zip(names, tcols))
        d = dict(kind="torque", file=f"{name}.csv", split=split, columns=cmap)
        if currents:
            # the exact transmission (a wrong constant would be an unmodelled drive gain, not a null)
            d["scale"] = {c: float(k_t[m] * gear[m]) for m, c in enumerate(tcols)}
            d["offset"] = {c: float(i0[m]) for m, c in enumerate(tcols)}
        ds.append(d)
    RL._case_yaml(folder, ds, tool, true, (Fv, Fc))

    traits = dict(tr, noise_pct=noise_pct.tolist(), noise_ar1_pole=pole, fs_hz=fs, record_s=T)
    if tr["hum"]:
        traits["hum_nm"] = {m: float(a) for m, a in zip(names, hum_amp)}
        traits["hum_hz"] = HUM_HZ
    traits["encoder_counts_per_rev"] = counts
    traits["angle_step_rad"] = q_step
    if tr["clip"]:
        traits["clip_channel"] = dict(joint=names[jc], index=jc, limit=limits, share_target=share, share=clip_share,
                                      unit="A" if currents else "N m")
    if adc_step is not None:
        traits["adc"] = dict(bits=12, codes=ADC_CODES, step={m: s for m, s in zip(names, adc_step)},
                             unit="A" if currents else "N m")
    if currents:
        traits["transmission"] = dict(gear=gear.tolist(), torque_constant=k_t.tolist(), current_offset_a=i0.tolist())
    if stamps:
        traits["stamps_detail"] = stamps
    if tracking:
        traits["tracking_error_max_rad"] = tracking
    if P is not None:
        traits.update(period_s=P, periods=PERIODS)
    truth = dict(kind="torque", robot=robot, family="null", effects=[], expected_verdict="within_noise",
                 trait=code(tr), traits=traits, noise_std_nm={m: float(s) for m, s in zip(names, noise_std)},
                 dead_channels=[], cad_error=caderr,
                 realism=dict(fs_hz=fs, noise=tr["noise"], noise_ar1_pole=pole,
                              friction_Fv=Fv.tolist(), friction_Fc=Fc.tolist(), torque_std=scale.tolist()))
    (folder / "robot.urdf").write_text(R.urdf_text(cad, tool, robot))
    (folder / "truth.json").write_text(json.dumps(truth, indent=1, default=float))
    return folder, truth
