"""Tip records of the independent bench: the true robot with a flexible joint (a spring with the
motor's inertia on its far side) driven by applied torques from rest, integrated by
``scipy.integrate.solve_ivp`` on Pinocchio's dynamics, its tool position recorded with noise (a
laser tracker's view). No jflex code.

State ``[q (n), qd (n), theta, theta_d]``: the links with every rigid joint's rotor inertia
added to the diagonal of M(q), the flexible joint's link driven by the spring torque
``k (theta - q_j) + c (theta_d - qd_j)`` instead of the applied one, and its motor by
``I_m theta_dd = tau_j - spring``. Backlash inside the transmission (``flex = (j, k, c, b)``):
the elastic part is ``k dz(theta - q_j)`` with the sharp dead zone ``dz(d) = sign(d) max(|d| - b, 0)``
(the link free of the spring within ``b`` either side; the damper acts throughout).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from scipy.integrate import solve_ivp


def rest_motion(rng, q0, T, fs, f0=2.0, harmonics=3, amp=0.25):
    """A motion from rest at ``q0``: ``q0 + sum_k c_k (1 - cos(w_k t))``, exact derivatives."""
    n = len(q0)
    t = np.arange(int(round(T * fs))) / fs
    q = np.tile(np.asarray(q0, float), (t.size, 1))
    qd, qdd = np.zeros_like(q), np.zeros_like(q)
    for j in range(n):
        c = rng.normal(size=harmonics) / np.arange(1, harmonics + 1)
        c *= amp / np.sum(np.abs(c))
        for k in range(harmonics):
            w = 2 * np.pi * f0 * (k + 1)
            q[:, j] += c[k] * (1 - np.cos(w * t))
            qd[:, j] += c[k] * w * np.sin(w * t)
            qdd[:, j] += c[k] * w * w * np.cos(w * t)
    return t, q, qd, qdd


def applied_torques(model, rotor, q, qd, qdd):
    """Feed-forward motor torques of the rigid robot with its rotors along a motion (N, n)."""
    data = model.createData()
    return np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, qd, qdd)]) + np.asarray(rotor)[None] * qdd


def dead_zone(d, b):
    """Sharp dead zone of half-width ``b``: ``sign(d) max(|d| - b, 0)``."""
    return np.sign(d) * max(abs(d) - b, 0.0)


def simulate_tip(model, tool, rotor, t, tau, q0, flex=None):
    """Tool positions (N, 3) [m] of ``model`` from rest at ``q0`` under the applied torques ``tau``
    (N, n) sampled at ``t`` (linear interpolation), the rotors' inertias ``rotor`` (n,) on the
    links' side; ``flex = (j, k, c)``: joint ``j`` a spring to its motor (``rotor[j]`` then on the
    motor side); ``(j, k, c, b)``: with play of half-width ``b`` [rad] inside the transmission."""
    data = model.createData()
    n = model.nq
    fid = model.getFrameId(tool)
    rot = np.asarray(rotor, float).copy()
    j, b = None, 0.0
    if flex is not None:
        j, k, c = flex[:3]
        b = float(flex[3]) if len(flex) > 3 else 0.0
        im = rot[j]
        rot[j] = 0.0

    def tau_at(s):
        return np.array([np.interp(s, t, tau[:, i]) for i in range(n)])

    def rhs(s, x):
        q, qd = x[:n], x[n:2 * n]
        u = tau_at(s)
        M = pin.crba(model, data, q) + np.diag(rot)
        h = pin.nonLinearEffects(model, data, q, qd)
        out = np.empty_like(x)
        out[:n] = qd
        if j is None:
            out[n:2 * n] = np.linalg.solve(M, u - h)
            return out
        th, thd = x[2 * n], x[2 * n + 1]
        d = th - q[j]
        spring = k * dead_zone(d, b) + c * (thd - qd[j])
        ul = u.copy()
        ul[j] = spring
        out[n:2 * n] = np.linalg.solve(M, ul - h)
        out[2 * n] = thd
        out[2 * n + 1] = (u[j] - spring) / im
        return out

    g = pin.computeGeneralizedGravity(model, data, np.asarray(q0, float))
    # at rest the spring holds the link's gravity torque: deflected b past the play in its direction
    x0 = np.concatenate([q0, np.zeros(n)] + ([[q0[j] + g[j] / k + np.sign(g[j]) * b, 0.0]] if j is not None else []))
    sol = solve_ivp(rhs, (t[0], t[-1]), x0, method="DOP853", t_eval=t, rtol=1e-9, atol=1e-11,
                    max_step=float(t[1] - t[0]))
    if not sol.success:
        raise RuntimeError(f"solve_ivp failed: {sol.message}")
    out = []
    for q in sol.y[:n].T:
        pin.framesForwardKinematics(model, data, q)
        out.append(data.oMf[fid].translation.copy())
    return np.array(out)
