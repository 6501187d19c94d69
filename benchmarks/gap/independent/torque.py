"""Joint-torque records of a robot with hidden effects, made with Pinocchio and SciPy.

The robot tracks a smooth periodic reference (:class:`signals.Fourier`); the motor encoders read
it. The torques are Pinocchio's inverse dynamics of the *true* robot along it plus the effects'
torques; effects that change the link motion (a flexible joint, backlash in a compliant
transmission) are simulated with ``scipy.integrate.solve_ivp``: the motor side follows the
reference, the link of that joint is free, the other joints track rigidly. What the records
carry is what a controller logs: encoder angles (quantised) and motor torques (delayed,
filtered, coloured noise), sampled at a few hundred Hz.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from scipy.integrate import solve_ivp

from .robots import add_payload

COULOMB_WIDTH = 0.01  # [rad/s] width of tanh in the true Coulomb law (a real joint is not a sign)


def rnea_batch(model, q, qd, qdd):
    data = model.createData()
    return np.stack([pin.rnea(model, data, a, b, c).copy() for a, b, c in zip(q, qd, qdd)])


def gravity_batch(model, q):
    data = model.createData()
    return np.stack([pin.computeGeneralizedGravity(model, data, a).copy() for a in q])


def compensator_torque(q, k, a, r, l0, phi0):
    """Torque of a spring balancer (anchored at ``a`` from the joint axis on the previous link,
    attached at ``r`` on the moving link, free length ``l0``) at joint angle ``q``."""
    phi = q + phi0
    l = np.sqrt(a * a + r * r - 2 * a * r * np.cos(phi))
    return k * (l - l0) * a * r * np.sin(phi) / l


def additive(effect, p, q, qd, qdd, j):
    """Torque (N,) at joint ``j`` that an algebraic effect adds along (q, qd, qdd)."""
    v = qd[:, j]
    if effect == "viscous_friction":
        return p["Fv"] * v
    if effect == "coulomb_friction":
        return p["Fc"] * np.tanh(v / COULOMB_WIDTH)
    if effect == "stribeck_friction":
        # the hump of static friction over the Coulomb level the nominal model already has
        return (p["Fs"] - p["Fc"]) * np.exp(-(np.abs(v) / p["vs"]) ** 2) * np.tanh(v / COULOMB_WIDTH)
    if effect == "rotor_inertia":
        return p["Ia"] * qdd[:, j]
    if effect == "gravity_compensator":
        return compensator_torque(q[:, j], p["k"], p["a"], p["r"], p["l0"], p["phi0"])
    if effect == "cogging":
        return p["A"] * np.sin(p["periods"] * q[:, j] + p["phase"])
    raise KeyError(effect)


def simulate_spring(model, traj, j, spring, t_eval, p, warmup=2.0):
    """Link ``j`` driven by its motor (which follows ``traj``) through a spring; every other joint
    follows ``traj`` rigidly. ``spring``: ``flexible`` (``k``, ``c``) or ``backlash`` (contact
    stiffness ``k``, damping ``c``, half-width ``b``). Returns ``(q_link (N, n), qd, qdd, tau_spring (N,))``
    at ``t_eval`` (the motor angle of joint j is ``traj``)."""
    data = model.createData()
    k, c = p["k"], p["c"]
    b = p.get("b", 0.0)

    def spring_torque(d, dd):
        if spring == "flexible":
            return k * d + c * dd
        # dead zone of half-width b: contact force and contact damping only when engaged
        e = np.sign(d) * max(abs(d) - b, 0.0)
        return k * e + (c * dd if e != 0.0 else 0.0)

    def state(t, x):
        q, qd, qdd = traj(t)[0], traj(t, 1)[0], traj(t, 2)[0]
        th, thd = q[j], qd[j]
        q[j], qd[j] = x[0], x[1]
        ts = spring_torque(th - x[0], thd - x[1])
        a0 = qdd.copy()
        a0[j] = 0.0
        bias = pin.rnea(model, data, q, qd, a0)[j]
        Mjj = pin.crba(model, data, q)[j, j]
        qdd[j] = (ts - bias) / Mjj
        return q, qd, qdd, ts

    def rhs(t, x):
        _, _, qdd, _ = state(t, x)
        return [x[1], qdd[j]]

    t0 = t_eval[0] - warmup
    q0, qd0 = traj(t0)[0], traj(t0, 1)[0]
    g = pin.computeGeneralizedGravity(model, data, q0)[j]
    x0 = [q0[j] - g / k - np.sign(g) * b, qd0[j]]
    fmax = np.sqrt(k / max(pin.crba(model, data, q0)[j, j], 1e-6)) / (2 * np.pi)
    sol = solve_ivp(rhs, (t0, t_eval[-1]), x0, method="DOP853", t_eval=t_eval, rtol=1e-9, atol=1e-11,
                    max_step=0.05 / fmax)
    if not sol.success:
        raise RuntimeError(f"solve_ivp failed: {sol.message}")
    out = [state(t, x) for t, x in zip(sol.t, sol.y.T)]
    return tuple(np.stack([o[i] for o in out]) if i < 3 else np.array([o[3] for o in out]) for i in range(4))


def true_torque(model, tool, traj, effects, friction, t):
    """Motor torques (N, n) of the true robot at times ``t`` along the reference ``traj``.

    ``effects``: list of ``(name, joint, params)`` acting on the physics (not on the sensor);
    ``friction``: ``(Fv (n,), Fc (n,))`` the every-joint friction (viscous + tanh Coulomb)."""
    q, qd, qdd = traj(t), traj(t, 1), traj(t, 2)
    for name, j, p in effects:
        if name == "payload":
            model = add_payload(model, tool, p["m"], p["offset"], p["radius"])
    sims = [(name, j, p) for name, j, p in effects if name in ("joint_flexibility", "backlash")]
    if len(sims) > 1:
        raise ValueError("one simulated transmission per record")
    if sims:
        name, j, p = sims[0]
        ql, qdl, qddl, ts = simulate_spring(model, traj, j, "flexible" if name == "joint_flexibility" else "backlash", t, p)
        tau = rnea_batch(model, ql, qdl, qddl)
        tau[:, j] = ts  # the motor (massless in this model) passes the spring torque on
    else:
        tau = rnea_batch(model, q, qd, qdd)
    Fv, Fc = friction
    tau += Fv[None] * qd + Fc[None] * np.tanh(qd / COULOMB_WIDTH)
    for name, j, p in effects:
        if name not in ("payload", "joint_flexibility", "backlash", "sensor_delay"):
            tau[:, j] += additive(name, p, q, qd, qdd, j)
    return tau
