"""Torque cases with real robots' effects, made by independent code (Pinocchio + NumPy, none of
jflex): the robot tracks a Fourier reference, the motor torques are Pinocchio's inverse dynamics
of the true robot plus the joints' friction (declared in the case) plus one planted effect, with
coloured noise; the encoders are quantised. Written as a case folder by the independent bench's
writer (benchmarks/gap/independent)."""

import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "gap"))
from independent import cases as C  # noqa: E402
from independent import robots as R  # noqa: E402
from independent import signals as S  # noqa: E402
from independent import torque as TQ  # noqa: E402

WIDTH = 0.01  # [rad/s] the true smooth sign's width


def planted_torque(effect, p, q, qd, qdd):
    """(N, n) torque the planted effect adds (NumPy)."""
    out = np.zeros_like(q)
    if effect == "torque_offset":
        out[:, p["joint"]] = p["offset"]
    elif effect == "asymmetric_coulomb":
        s = np.tanh(qd[:, p["joint"]] / WIDTH)
        out[:, p["joint"]] = p["positive"] * 0.5 * (1 + s) - p["negative"] * 0.5 * (1 - s)
    elif effect == "coupled_drive":
        a, b = p["joints"]
        K = np.asarray(p["K"], float)  # (1, 2): the motor's velocity K @ [qd_a, qd_b]
        w, wd = qd[:, [a, b]] @ K.T, qdd[:, [a, b]] @ K.T
        fm = p["Ia"] * wd + p["fv"] * w + p["fc"] * np.tanh(w / WIDTH)
        out[:, [a, b]] = fm @ K
    elif effect not in ("sensor_delay", None):
        raise KeyError(effect)
    return out


def make(folder, robot="ur5", effect=None, size=0.15, seed=0, delay=0.0, T=3.0, fs=250.0, logged_gain=1.0):
    """A case folder with ``effect`` planted at ``size`` x the joint's torque spread (``delay`` [s]:
    the torque channel lags the angles, negative: leads them; ``logged_gain``: what the log holds is
    the torque times this, a motor current whose scale the case forgets, or one per joint: torque
    constants off). Returns ``(folder, truth)``."""
    rng = np.random.default_rng(seed)
    true, tool, home = R.true_model(robot)
    nom, _ = R.cad_error(true, rng)
    n = true.nq
    t = np.arange(int(round(T * fs))) / fs
    amp = C._amp(true, home, 0.5)
    trajs = [S.Fourier(rng, home + rng.uniform(-0.15, 0.15, n) * (amp > 0.3), amp, f0=1.0 / T) for _ in range(3)]
    q, qd, qdd = trajs[0](t), trajs[0](t, 1), trajs[0](t, 2)
    scale = TQ.rnea_batch(true, q, qd, qdd).std(axis=0)
    Fv = rng.uniform(0.03, 0.08, n) * scale / qd.std(axis=0)
    Fc = rng.uniform(0.03, 0.08, n) * scale
    p = {}
    if effect == "torque_offset":
        j = int(rng.integers(0, n))
        p = dict(joint=j, offset=float(size * scale[j] * rng.choice([-1, 1])))
    elif effect == "asymmetric_coulomb":
        j = int(rng.integers(0, n))
        p = dict(joint=j, positive=float(size * scale[j]), negative=float(0.2 * size * scale[j]))
        Fc[j] = 0.0  # the planted law is the joint's whole dry friction; the case knows of none there
    elif effect == "coupled_drive":
        a, b = n - 2, n - 1
        w = qd[:, [a, b]] @ np.array([1.0, 1.0])
        wd = qdd[:, [a, b]] @ np.array([1.0, 1.0])
        s = scale[[a, b]].max()
        p = dict(joints=[a, b], K=[[1.0, 1.0]], Ia=float(size * s / wd.std()), fv=float(0.5 * size * s / w.std()),
                 fc=float(0.5 * size * s))
    datasets = []
    for i, tr in enumerate(trajs):
        tt = t - delay
        qa, qda, qdda = tr(tt), tr(tt, 1), tr(tt, 2)
        tau = TQ.rnea_batch(true, qa, qda, qdda) + Fv * qda + Fc * np.tanh(qda / WIDTH) + planted_torque(effect, p, qa, qda, qdda)
        tau = tau + S.ar1_noise(rng, tau.shape, 0.7, 0.01 * tau.std(axis=0))
        datasets.append(("torque", f"traj{i}", "train" if i < 2 else "validation",
                         dict(t=t, q=S.quantise(tr(t), 2 * np.pi / 2**19), tau=np.asarray(logged_gain, float) * tau)))
    names = [true.names[k + 1] for k in range(n)]
    coulomb = [names[k] for k in range(n) if Fc[k] > 0]
    nominal = [dict(effect="viscous_friction", joint="all"),
               dict(effect="coulomb_friction", joint="all" if len(coulomb) == n else coulomb)]
    truth = dict(effect=effect, params=p, delay=delay, joint_names=names, torque_std=scale.tolist(),
                 logged_gain=np.broadcast_to(np.asarray(logged_gain, float), (n,)).tolist())
    return C._write(folder, nom, tool, robot, nominal, datasets, truth), truth
