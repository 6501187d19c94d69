"""A foreign engine for the withheld-effect bench: the same robot simulated by MuJoCo with its own
joint armature, damping, dry friction (``frictionloss``, a constraint, not a smooth law) and
springs. jflex only sees the recorded motion and actuator torques."""

from __future__ import annotations

import numpy as np

from .generate import fourier_trajectory, rigid_torque

# MuJoCo joint attribute -> the candidate name it stands for
MUJOCO_EFFECTS = {"armature": "rotor_inertia", "damping": "viscous_friction", "frictionloss": "coulomb_friction",
                  "stiffness": "gravity_compensator"}


def _quat(R):
    import scipy.spatial.transform as st

    x, y, z, w = st.Rotation.from_matrix(np.asarray(R)).as_quat()
    return f"{w} {x} {y} {z}"


def mjcf(robot, joint_attrs: dict) -> str:
    """MJCF text of a serial ``robot``; ``joint_attrs[i]`` extra attributes of joint i."""
    R, P, A, I = (np.asarray(a) for a in (robot.placement_R, robot.placement_p, robot.axis, robot.inertia))
    g = np.asarray(robot.gravity)
    body = ""
    for i in reversed(range(robot.nq)):
        m = I[i, 0]
        c = I[i, 1:4] / m
        Io = np.array([[I[i, 4], I[i, 5], I[i, 7]], [I[i, 5], I[i, 6], I[i, 8]], [I[i, 7], I[i, 8], I[i, 9]]])
        Ic = Io - m * (c @ c * np.eye(3) - np.outer(c, c))
        attrs = " ".join(f'{k}="{v}"' for k, v in joint_attrs.get(i, {}).items())
        body = (f'<body name="{robot.link_names[i]}" pos="{P[i][0]} {P[i][1]} {P[i][2]}" quat="{_quat(R[i])}">'
                f'<joint name="{robot.joint_names[i]}" type="hinge" axis="{A[i][0]} {A[i][1]} {A[i][2]}" {attrs}/>'
                f'<inertial pos="{c[0]} {c[1]} {c[2]}" mass="{m}" fullinertia="{Ic[0,0]} {Ic[1,1]} {Ic[2,2]} {Ic[0,1]} {Ic[0,2]} {Ic[1,2]}"/>'
                f"{body}</body>")
    acts = "".join(f'<motor joint="{j}" gear="1"/>' for j in robot.joint_names)
    return (f'<mujoco><option timestep="0.0005" gravity="{g[0]} {g[1]} {g[2]}" integrator="RK4"/>'
            f"<worldbody>{body}</worldbody><actuator>{acts}</actuator></mujoco>")


def simulate_mujoco(robot, joint_attrs, rng, T=10.0, fs=200.0):
    """Track a Fourier reference with computed torque (nominal model) + PD in MuJoCo; return the
    recorded (t, q, qd, qdd, tau) at ``fs``."""
    import mujoco

    m = mujoco.MjModel.from_xml_string(mjcf(robot, joint_attrs))
    d = mujoco.MjData(m)
    tr, qr, qdr, qddr = fourier_trajectory(robot.nq, rng, T=T, fs=1.0 / m.opt.timestep)
    ff = rigid_torque(robot, qr, qdr, qddr)
    d.qpos[:] = qr[0]
    d.qvel[:] = qdr[0]
    every = int(round(1.0 / (fs * m.opt.timestep)))
    kp, kd = 400.0, 40.0
    Mdiag = np.abs(np.diag(np.asarray(ff.std(axis=0)))) + 1.0
    out = []
    for k in range(len(tr)):
        u = ff[k] + Mdiag.diagonal() * (kp * (qr[k] - d.qpos) + kd * (qdr[k] - d.qvel)) / 10.0
        d.ctrl[:] = u
        mujoco.mj_step(m, d)
        if k % every == 0:
            # qacc of the step just taken goes with the state before it: record the pair consistently
            out.append((tr[k], d.qpos.copy(), d.qvel.copy(), d.qacc.copy(), u.copy()))
    t = np.array([o[0] for o in out])
    q, qd, qdd, tau = (np.array([o[i] for o in out]) for i in range(1, 5))
    return t, q, qd, qdd, tau
