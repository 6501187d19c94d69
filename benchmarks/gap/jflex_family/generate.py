"""Synthetic cases with hidden truths, for the withheld-effect bench, the tests and the demo.

The data never come from the candidates' own equations: each truth is drawn from a richer form
(Stribeck with a non-Gaussian shape and an arctan sign, a spring compensator, a payload with its
own rotational inertia, a play operator with smooth engagement, a delay behind an anti-alias
filter, coupled bearing compliance, bending hinges off mid-span, ...) or, for one family, comes
from a foreign engine (MuJoCo: its frictionloss, armature, damping and joint springs).
A case folder holds ``case.yaml``, the robot and the NPZ files; the truth goes to a separate
``truth.json`` next to it, which only the scorer reads.
"""

from __future__ import annotations

import json
import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import yaml

from jflex._config import load_robot
from jflex._dynamics import rnea
from jflex._spatial import params_from_com
from jflex.gap.frequency import _model as L

# --- robots (written as DH YAML so the case is self-contained) -------------------------------------
ROBOTS = {
    "arm3": dict(
        name="arm3", dh=dict(convention="modified", columns=["alpha", "a", "d", "theta"], angles="deg",
                             rows=[[0, 0.0, 0.45, 0], [90, 0.15, 0.0, 0], [0, 0.6, 0.0, 0]], tool=[0, 0.5, 0.0, 0]),
        joint_names=["joint1", "joint2", "joint3"], gravity=[0, 0, -9.81],
        links=[dict(mass=12.0, com=[0, 0, -0.1], inertia=[0.3, 0, 0.3, 0, 0, 0.2]),
               dict(mass=8.0, com=[0.3, 0, 0.02], inertia=[0.05, 0, 0.3, 0, 0, 0.3]),
               dict(mass=4.0, com=[0.25, 0.01, 0], inertia=[0.02, 0, 0.1, 0, 0, 0.1])]),
    "planar2": dict(
        name="planar2", dh=dict(convention="modified", columns=["alpha", "a", "d", "theta"], angles="deg",
                                rows=[[90, 0.0, 0.3, 0], [0, 0.5, 0.0, 0]], tool=[0, 0.4, 0.0, 0]),
        joint_names=["shoulder", "elbow"], gravity=[0, 0, -9.81],
        links=[dict(mass=6.0, com=[0.25, 0, 0], inertia=[0.02, 0, 0.15, 0, 0, 0.15]),
               dict(mass=3.0, com=[0.2, 0, 0], inertia=[0.01, 0, 0.06, 0, 0, 0.06])]),
    "arm4": dict(
        name="arm4", dh=dict(convention="modified", columns=["alpha", "a", "d", "theta"], angles="deg",
                             rows=[[0, 0.0, 0.4, 0], [90, 0.1, 0.0, 0], [0, 0.55, 0.0, 0], [0, 0.45, 0.0, 0]],
                             tool=[0, 0.15, 0.0, 0]),
        joint_names=["j1", "j2", "j3", "j4"], gravity=[0, 0, -9.81],
        links=[dict(mass=10.0, com=[0, 0, -0.1], inertia=[0.2, 0, 0.2, 0, 0, 0.15]),
               dict(mass=7.0, com=[0.27, 0, 0], inertia=[0.04, 0, 0.2, 0, 0, 0.2]),
               dict(mass=4.0, com=[0.22, 0, 0], inertia=[0.02, 0, 0.08, 0, 0, 0.08]),
               dict(mass=1.5, com=[0.07, 0, 0], inertia=[0.005, 0, 0.006, 0, 0, 0.006])]),
}


def write_robot(folder: pathlib.Path, name: str) -> pathlib.Path:
    p = folder / "robot.yaml"
    p.write_text(yaml.safe_dump(ROBOTS[name], sort_keys=False))
    return p


# --- trajectories --------------------------------------------------------------------------------
def fourier_trajectory(n, rng, T=10.0, fs=200.0, f0=0.1, harmonics=5, amp=0.8, center=None):
    """Band-limited periodic excitation with exact derivatives: (t, q, qd, qdd)."""
    t = np.arange(int(T * fs)) / fs
    center = rng.uniform(-0.5, 0.5, n) if center is None else np.asarray(center)
    q, qd, qdd = (np.tile(center, (t.size, 1)) * c for c in (1.0, 0.0, 0.0))
    for j in range(n):
        a = rng.normal(size=harmonics) / np.arange(1, harmonics + 1)
        b = rng.normal(size=harmonics) / np.arange(1, harmonics + 1)
        s = amp / np.sqrt(np.sum(a**2 + b**2))
        for k in range(harmonics):
            w = 2 * np.pi * f0 * (k + 1)
            q[:, j] += s * (a[k] * np.sin(w * t) + b[k] * np.cos(w * t))
            qd[:, j] += s * w * (a[k] * np.cos(w * t) - b[k] * np.sin(w * t))
            qdd[:, j] += -s * w * w * (a[k] * np.sin(w * t) + b[k] * np.cos(w * t))
    return t, q, qd, qdd


@jax.jit
def _id_batch(robot, q, qd, qdd):
    return jax.vmap(lambda a, b, c: rnea(robot, a, b, c))(q, qd, qdd)


def rigid_torque(robot, q, qd, qdd):
    return np.array(_id_batch(robot, jnp.asarray(q), jnp.asarray(qd), jnp.asarray(qdd)))


def _atan_sign(v, eps=0.005):
    return 2 / np.pi * np.arctan(v / eps)


# --- torque truths (richer forms) ------------------------------------------------------------------
def torque_truth(robot, effect, joint, params, t, q, qd, qdd):
    """Torque (N, n) the truth effect adds (or the whole torque for effects that change the motion)."""
    N, n = q.shape
    out = np.zeros((N, n))
    j = joint
    if effect == "viscous_friction":
        # viscous plus a small quadratic (fluid) drag: not the candidate's linear law
        out[:, j] = params["Fv"] * qd[:, j] + 0.1 * params["Fv"] * qd[:, j] * np.abs(qd[:, j])
    elif effect == "coulomb_friction":
        out[:, j] = params["Fc"] * _atan_sign(qd[:, j])
    elif effect == "stribeck_friction":
        v = np.abs(qd[:, j]) / params["vs"]
        out[:, j] = (params["Fc"] + (params["Fs"] - params["Fc"]) * np.exp(-v**1.4)) * _atan_sign(qd[:, j])
    elif effect == "rotor_inertia":
        out[:, j] = params["Ia"] * qdd[:, j]
    elif effect == "gravity_compensator":
        k, Lc, r, x0, off = params["k"], params["L"], params["r"], params["x0"], np.pi / 2
        g = off - q[:, j]
        l = np.sqrt(Lc**2 + r**2 - 2 * Lc * r * np.cos(g))
        tau_gc = k * (l - x0) * Lc * r * np.sin(g) / l  # spring torque on the joint (Eq. 2.9 form)
        out[:, j] = -tau_gc
    elif effect == "payload":
        inert = np.asarray(robot.inertia).copy()
        body, kf = robot.frame_index("tool")
        p = np.asarray(robot.frame_p[kf]) + np.array(params["offset"])
        m, rad = params["m"], 0.06
        # a solid sphere about its own centre (its rotational inertia is not in the candidate's 4 parameters)
        inert[body] += np.asarray(params_from_com(m, p, 0.4 * m * rad**2 * np.eye(3)))
        out = rigid_torque(robot.replace(inertia=inert), q, qd, qdd) - rigid_torque(robot, q, qd, qdd)
    return out


def play(x, b):
    """Play (backlash) operator of half-width b."""
    y = np.empty_like(x)
    y[0] = x[0]
    for i in range(1, len(x)):
        y[i] = min(max(y[i - 1], x[i] - b), x[i] + b)
    return y


def _smooth(x, fs, sigma_s=0.01):
    k = np.arange(-int(4 * sigma_s * fs), int(4 * sigma_s * fs) + 1) / fs
    g = np.exp(-0.5 * (k / sigma_s) ** 2)
    g /= g.sum()
    xp = np.pad(x, (len(k) // 2, len(k) // 2), mode="edge")
    return np.convolve(xp, g, mode="valid")


def torque_data(robot, truths, t, q, qd, qdd, rng, noise, nominal_friction=None):
    """Measured (q, qd, qdd, tau) under the hidden truths (list of (effect, joint, params))."""
    fs = 1.0 / (t[1] - t[0])
    ql, qdl, qddl = q.copy(), qd.copy(), qdd.copy()
    delay = 0.0
    for eff, j, p in truths:
        if eff == "backlash":
            # motor-side encoder; the link follows through a play of half-width b, engaging smoothly
            ql[:, j] = _smooth(play(q[:, j], p["b"]), fs)
            qdl[:, j] = np.gradient(ql[:, j], t)
            qddl[:, j] = np.gradient(_smooth(qdl[:, j], fs), t)
        if eff == "sensor_delay":
            delay = p["d"]
    tau = rigid_torque(robot, ql, qdl, qddl)
    for eff, j, p in truths:
        if eff not in ("backlash", "sensor_delay"):
            tau += torque_truth(robot, eff, j, p, t, ql, qdl, qddl)
    if nominal_friction is not None:
        Fv, Fc = nominal_friction
        tau += Fv * qdl + Fc * _atan_sign(qdl, 0.01)
    if delay:
        # a delayed sensor behind a first-order anti-alias filter (time constant 2 ms)
        tau_d = np.stack([np.interp(t - delay, t, tau[:, k]) for k in range(tau.shape[1])], axis=1)
        a = np.exp(-1 / (fs * 0.002))
        for i in range(1, len(t)):
            tau_d[i] = a * tau_d[i - 1] + (1 - a) * tau_d[i]
        tau = tau_d
    tau = tau + rng.normal(size=tau.shape) * noise * tau.std(axis=0)
    return tau


# --- frequency truths ------------------------------------------------------------------------------
def frf_truth(robot, tool, springs, K, laws, q0, freq, payload=None):
    """Tool receptance (F, 3, 3) of a truth with a full spring matrix ``K`` (S, S) (coupling allowed)
    and per-spring laws ``[(law, value, alpha)]``; optional payload ``(m, offset)``."""
    lm = L.FrequencyModel(robot, L.Structure(tuple(springs)), tool)
    P = lm.mats(q0)
    M, Kg = P.M, P.Kg
    if payload is not None:
        body, kf = lm.aug.frame_index(tool)
        inert = np.asarray(lm.aug.inertia).copy()
        p = np.asarray(lm.aug.frame_p[kf]) + np.asarray(payload[1])
        inert[body] += np.asarray(params_from_com(payload[0], p, 0.4 * payload[0] * 0.06**2 * np.eye(3)))
        lm2 = L.FrequencyModel(robot, L.Structure(tuple(springs)), tool)
        lm2.aug = lm.aug.replace(inertia=inert)
        P2 = lm2.mats(q0)
        M, Kg = P2.M, P2.Kg
    w = 2 * np.pi * np.asarray(freq)
    S = len(springs)
    out = np.empty((len(w), 3, 3), complex)
    for i, wi in enumerate(w):
        D = (Kg + K - wi**2 * M).astype(complex)
        for s, (law, v, al) in enumerate(laws):
            if law == "viscous":
                D[s, s] += 1j * wi * v
            elif law == "hysteretic":
                D[s, s] += 1j * v * K[s, s]
            elif law == "fractional":
                D[s, s] += v * (1j * wi) ** al
            elif law == "mixed":  # viscous plus a hysteretic share
                D[s, s] += 1j * wi * v + 1j * 0.01 * K[s, s]
        out[i] = P.J @ np.linalg.solve(D, P.J.T.astype(complex))
    return out


def write_case(folder, robot_name, datasets, nominal, tool="tool", truth=None, extra=None):
    """Write ``case.yaml`` + NPZs (``datasets``: list of (kind, name, split, arrays)); the truth to
    ``truth.json`` beside the case folder's data (read by the scorer only)."""
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    write_robot(folder, robot_name)
    ds = []
    for kind, name, split, arrs in datasets:
        np.savez(folder / f"{name}.npz", **arrs)
        ds.append(dict(kind=kind, file=f"{name}.npz", split=split))
    cfg = dict(robot="robot.yaml", tool_frame=tool, nominal_effects=nominal, datasets=ds)
    if extra:
        cfg.update(extra)
    (folder / "case.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    if truth is not None:
        (folder.parent / f"{folder.name}.truth.json").write_text(json.dumps(truth, indent=1))
    return folder


# --- case families -----------------------------------------------------------------------------------
TORQUE_PARAM_DRAW = {
    "viscous_friction": lambda rng, s: {"Fv": s * rng.uniform(0.3, 0.6)},
    "coulomb_friction": lambda rng, s: {"Fc": s * rng.uniform(0.15, 0.3)},
    "stribeck_friction": lambda rng, s: {"Fc": s * rng.uniform(0.1, 0.2), "Fs": s * rng.uniform(0.35, 0.5),
                                         "vs": rng.uniform(0.05, 0.2)},
    "rotor_inertia": lambda rng, s: {"Ia": s * rng.uniform(0.05, 0.1)},
    "gravity_compensator": lambda rng, s: {"k": s * rng.uniform(0.3, 0.6) / (0.25 * 0.12), "L": 0.25, "r": 0.12, "x0": 0.05},
    "payload": lambda rng, s: {"m": rng.uniform(1.5, 4.0), "offset": list(rng.uniform(-0.03, 0.03, 3))},
    "backlash": lambda rng, s: {"b": rng.uniform(0.01, 0.02)},
    "sensor_delay": lambda rng, s: {"d": rng.uniform(0.008, 0.03)},
}
JOINTLESS = ("payload", "sensor_delay")


def rest_trajectory(n, rng, q0, T=1.5, fs=200.0, f0=0.6, harmonics=3, amp=0.3):
    """A motion that starts at rest at ``q0``: ``q0 + sum_k c_k (1 - cos(w_k t))`` per joint, exact
    derivatives: (t, q, qd, qdd)."""
    t = np.arange(int(T * fs)) / fs
    q, qd, qdd = (np.tile(np.asarray(q0, float), (t.size, 1)) * c for c in (1.0, 0.0, 0.0))
    for j in range(n):
        c = rng.normal(size=harmonics) / np.arange(1, harmonics + 1)
        c *= amp / np.sum(np.abs(c))
        for k in range(harmonics):
            w = 2 * np.pi * f0 * (k + 1)
            q[:, j] += c[k] * (1 - np.cos(w * t))
            qd[:, j] += c[k] * w * np.sin(w * t)
            qdd[:, j] += c[k] * w * w * np.cos(w * t)
    return t, q, qd, qdd


def tool_positions(robot, q, frame="tool"):
    """Origin (N, 3) [m] of ``frame`` in base axes along the motion ``q`` (N, n)."""
    from jflex._dynamics import frame_placement

    return np.asarray(jax.jit(jax.vmap(lambda a: frame_placement(robot, a, frame)[:3, 3]))(jnp.asarray(q)))


def torque_case(folder, robot_name, truths, seed, noise=0.01, nominal_friction=False, n_train=2, n_val=1,
                angle_noise=None, tip_noise=None):
    """A torque case: ``truths`` list of effect names (joint chosen at random where it applies).

    ``angle_noise`` [rad]: write the validation sets as ``response`` data instead, the applied
    torques exact and the joint angles measured with that white noise. ``tip_noise`` [m]: write
    them as tip-only ``response`` data (``tip_x``, ``tip_y``, ``tip_z`` of the tool frame, with
    that white noise) of short motions from rest at a posture ``q0`` (:func:`rest_trajectory`),
    the applied torques being the truth's inverse dynamics along the motion.
    """
    rng = np.random.default_rng(seed)
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    robot = load_robot(write_robot(folder, robot_name))
    n = robot.nq
    # the torque scale of each joint sets the size of the hidden effects
    t, q, qd, qdd = fourier_trajectory(n, np.random.default_rng(seed + 999))
    scale = rigid_torque(robot, q, qd, qdd).std(axis=0)
    drawn, truth = [], []
    used = set()
    for eff in truths:
        if eff in JOINTLESS:
            j = None
        elif eff == "gravity_compensator":
            j = 1  # the shoulder: the joint gravity loads most
        else:
            choices = [k for k in range(n) if (eff, k) not in used]
            j = int(rng.choice(choices))
        used.add((eff, j))
        s = scale[j] if j is not None else 1.0
        p = TORQUE_PARAM_DRAW[eff](rng, s if eff not in ("backlash", "sensor_delay", "payload") else 1.0)
        if eff == "rotor_inertia":
            p["Ia"] = float(scale[j] / np.abs(qdd[:, j]).std() * rng.uniform(0.15, 0.3))
        if eff == "viscous_friction":
            p["Fv"] = float(scale[j] / qd[:, j].std() * rng.uniform(0.15, 0.3))
        drawn.append((eff, j, p))
        truth.append(dict(effect=eff, joint=None if j is None else robot.joint_names[j], params=p))
    fric = None
    nominal = []
    if nominal_friction:
        # the nominal model already has friction at every joint, except a law the truth itself adds
        laws = {"viscous_friction", "coulomb_friction"} - set(truths)
        if "stribeck_friction" in truths:
            laws.discard("coulomb_friction")
        Fv = scale / qd.std(axis=0) * rng.uniform(0.05, 0.1, n) * ("viscous_friction" in laws)
        Fc = scale * rng.uniform(0.05, 0.1, n) * ("coulomb_friction" in laws)
        fric = (Fv, Fc)
        nominal = [dict(effect=e, joint="all") for e in sorted(laws)]
    dsets = []
    for i in range(n_train + n_val):
        tt, q, qd, qdd = fourier_trajectory(n, rng)
        split = "train" if i < n_train else "validation"
        if split == "validation" and tip_noise is not None:
            q0 = rng.uniform(-0.6, 0.6, n)
            tt, q, qd, qdd = rest_trajectory(n, rng, q0)
            tau = torque_data(robot, drawn, tt, q, qd, qdd, rng, 0.0, fric)
            y = tool_positions(robot, q) + tip_noise * rng.standard_normal((tt.size, 3))
            dsets.append(("response", f"tip{i}", split, dict(t=tt, tau=tau, y=y, channels=np.array(["tip_x", "tip_y", "tip_z"]),
                                                             q0=q0)))
            continue
        if split == "validation" and angle_noise is not None:
            tau = torque_data(robot, drawn, tt, q, qd, qdd, rng, 0.0, fric)
            y = q + angle_noise * rng.standard_normal(q.shape)
            dsets.append(("response", f"resp{i}", split, dict(t=tt, tau=tau, y=y, channels=np.array(robot.joint_names))))
            continue
        tau = torque_data(robot, drawn, tt, q, qd, qdd, rng, noise, fric)
        dsets.append(("torque", f"traj{i}", split, dict(t=tt, q=q, qd=qd, qdd=qdd, tau=tau)))
    return write_case(folder, robot_name, dsets, nominal,
                      truth=dict(effects=truth, family="torque", robot=robot_name, noise=noise))


FRF_FREQ = np.geomspace(3.0, 80.0, 360)


def flexible_tip_response(robot, K, C, Im, rng, tip_noise, q0=None, T=1.5, amp=0.3, f0=0.6, coupling=False):
    """A tip-only response record of a robot with a viscous torsion spring at every joint
    (stiffness ``K``, damping ``C``, rotor inertia ``Im`` on the motor side; ``coupling``: the
    rotor spins with its carrying link, the full model, which no candidate holds):
    the applied motor torques are the rigid feed-forward (with the rotor inertia) of a smooth
    motion from rest at ``q0``; the truth is simulated under them from rest (springs preloaded
    by gravity) and its tool position recorded with white noise ``tip_noise`` [m]."""
    import diffrax

    from jflex import simulate
    from jflex._inputs import Sampled
    from jflex._model import Model
    from jflex.effects import FlexibleJoints

    n = robot.nq
    q0 = rng.uniform(-0.6, 0.6, n) if q0 is None else np.asarray(q0, float)
    tt, q, qd, qdd = rest_trajectory(n, rng, q0, T=T, amp=amp, f0=f0)
    tau = rigid_torque(robot, q, qd, qdd) + np.asarray(Im)[None] * qdd
    model = Model(robot, [FlexibleJoints(jnp.asarray(K, float), jnp.asarray(C, float), jnp.asarray(Im, float), coupling=coupling)])
    g = rigid_torque(robot, q0[None], np.zeros((1, n)), np.zeros((1, n)))[0]
    x0 = np.concatenate([q0, q0 + g / np.asarray(K, float)])
    r = simulate(model, tt, jnp.asarray(x0), inputs=Sampled(tt, tau), outputs=("frame:tool",), solver=diffrax.Dopri8(),
                 rtol=1e-9, atol=1e-11, max_steps=400_000)
    y = np.asarray(r.outputs["frame:tool"]) + tip_noise * rng.standard_normal((tt.size, 3))
    return dict(t=tt, tau=tau, y=y, channels=np.array(["tip_x", "tip_y", "tip_z"]), q0=q0)


def frf_case(folder, robot_name, truths, seed, noise=0.01, n_post=3, tip_noise=None, frf_validation=True):
    """An FRF case on a robot with flexible joints (motors held), 2 training and 1-2 validation
    postures; ``truths``: effect names among joint_flexibility, orthogonal_compliance,
    link_flexibility, hysteretic_damping, fractional_damping, payload.

    ``tip_noise`` [m]: add a tip-only validation ``response`` set simulated from the truth
    (:func:`flexible_tip_response`; ``truths`` among joint_flexibility), the rotor inertias stated
    in the nominal model (``rotor_inertia`` with ``value``); ``frf_validation=False``: every FRF
    posture is a training set (the tip set is the only validation set)."""
    rng = np.random.default_rng(seed)
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    robot = load_robot(write_robot(folder, robot_name))
    n = robot.nq
    kj = np.array([4e4, 6e4, 2e4, 5e3][:n]) * rng.uniform(0.8, 1.25, n)
    cj = kj * rng.uniform(4e-4, 8e-4, n)
    springs = [L.Site("joint", j) for j in range(n)]
    laws = [["viscous", float(c), 0.5] for c in cj]
    Kd = list(kj)
    truth, nominal_joints = [], list(range(n))
    extra_springs, extra_k = [], []
    payload = None
    for eff in truths:
        j = int(rng.integers(0, n)) if eff not in ("payload",) else None
        if eff in ("orthogonal_compliance", "link_flexibility"):
            j = int(rng.integers(0, n - 1)) if eff == "link_flexibility" else int(rng.integers(0, n))
            kind = "orth" if eff == "orthogonal_compliance" else "link"
            frac_note = {}
            ss = [L.Site(kind, j, 0), L.Site(kind, j, 1)]
            if kind == "link":
                ss = [L.Site("link", j, a, frac=0.4) for a in (0, 1)]
                frac_note = {"hinge_at": 0.4}
            lm = L.FrequencyModel(robot, L.Structure(tuple(springs + extra_springs + ss)), "tool")
            P = lm.mats(np.zeros(n))
            ktarget = []
            for s in range(2):
                ii = len(springs) + len(extra_springs) + s
                fm = rng.uniform(25, 45)
                ktarget.append((2 * np.pi * fm) ** 2 * max(P.M[ii, ii], 1e-3))
            extra_springs += ss
            extra_k += ktarget
            truth.append(dict(effect=eff, joint=robot.joint_names[j] if kind == "orth" else None,
                              link=robot.link_names[j] if kind == "link" else None, params=dict(k=ktarget, **frac_note)))
        elif eff == "joint_flexibility":
            nominal_joints.remove(j)
            truth.append(dict(effect=eff, joint=robot.joint_names[j], params=dict(k=float(kj[j]))))
            laws[j][0] = "mixed"
        elif eff == "hysteretic_damping":
            eta = rng.uniform(0.04, 0.08)
            laws[j] = ["hysteretic", float(eta), 0.5]
            truth.append(dict(effect=eff, joint=robot.joint_names[j], params=dict(eta=eta)))
        elif eff == "fractional_damping":
            al = rng.uniform(0.3, 0.7)
            w = 2 * np.pi * 15
            laws[j] = ["fractional", float(cj[j] * w / w**al * 1.5), float(al)]
            truth.append(dict(effect=eff, joint=robot.joint_names[j], params=dict(alpha=al)))
        elif eff == "payload":
            payload = (float(rng.uniform(1.0, 3.0)), list(rng.uniform(-0.03, 0.03, 3)))
            truth.append(dict(effect=eff, joint=None, params=dict(m=payload[0])))
    S = n + len(extra_springs)
    K = np.zeros((S, S))
    K[:n, :n] = np.diag(Kd)
    for s in range(0, len(extra_k), 2):
        a, b = n + s, n + s + 1
        K[a, a], K[b, b] = extra_k[s], extra_k[s + 1]
        K[a, b] = K[b, a] = 0.3 * np.sqrt(extra_k[s] * extra_k[s + 1])  # coupled bearing / bending
    all_laws = laws + [["viscous", float(0.0015 * np.sqrt(extra_k[s])), 0.5] for s in range(len(extra_k))]
    postures = [np.concatenate([[0.0], rng.uniform(0.2, 1.2, 1), rng.uniform(-1.8, -0.6, 1), rng.uniform(-0.5, 0.5, n - 3)])[:n]
                if n >= 3 else rng.uniform(-1.0, 1.0, n) for _ in range(n_post)]
    dsets = []
    for i, q0 in enumerate(postures):
        H = frf_truth(robot, "tool", springs + extra_springs, K, all_laws, q0, FRF_FREQ, payload)
        scale = np.sqrt(np.mean(np.abs(H) ** 2, axis=0))
        # noise relative to the local response (coherence-limited) plus a small floor
        amp = noise * (np.abs(H) + 0.02 * scale[None])
        reps = H[None] + amp[None] * (rng.normal(size=(3,) + H.shape) + 1j * rng.normal(size=(3,) + H.shape)) / np.sqrt(2)
        dsets.append(("frf", f"frf_p{i}", "train" if i < n_post - 1 else "validation",
                      dict(q0=q0, freq=FRF_FREQ, H=reps.mean(axis=0), H_repeats=reps)))
    nominal = [dict(effect="joint_flexibility", joint=[robot.joint_names[j] for j in nominal_joints],
                    stiffness=[float(kj[j] * rng.uniform(0.85, 1.15)) for j in nominal_joints],
                    damping=[float(cj[j]) for j in nominal_joints])]
    if not frf_validation:
        dsets = [(k, nm, "train", a) for k, nm, _, a in dsets]
    if tip_noise is not None:
        if set(truths) - {"joint_flexibility"}:
            raise ValueError(f"frf_case: a tip response is simulated for joint_flexibility truths only, got {truths}")
        from jflex._dynamics import crba

        Mjj = np.diag(np.asarray(crba(robot, jnp.zeros(n))))
        Im = Mjj * rng.uniform(0.15, 0.3, n)
        dsets.append(("response", "tip", "validation", flexible_tip_response(robot, kj, cj, Im, rng, tip_noise, T=1.0, f0=2.0, amp=0.25)))
        nominal.append(dict(effect="rotor_inertia", joint="all", value=[float(v) for v in Im]))
        for t_ in truth:
            t_["params"]["rotor_inertia"] = [float(v) for v in Im]
    return write_case(folder, robot_name, dsets, nominal, truth=dict(effects=truth, family="frf", robot=robot_name, noise=noise))
