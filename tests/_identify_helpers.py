"""Shared fixtures of the identification tests: a 3-joint arm as a URDF (read by both jflex and
Pinocchio) and the seed-003 3-DOF DH arm."""

import numpy as np

import jflex

STAUBLI_DH = [[0, 0, 0.642, 0], [np.pi / 2, 0.25, 0, 0], [0, 0.95, 0, 0]]


def _random_com_inertia(rng):
    # Second moments of a mass distribution give principal moments that obey the triangle inequality.
    J = rng.uniform(0.02, 0.5, size=3)
    R, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return R @ np.diag([J[1] + J[2], J[0] + J[2], J[0] + J[1]]) @ R.T


def random_inertias(n, seed=0):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        I = _random_com_inertia(rng)
        out.append({"mass": float(rng.uniform(2, 20)), "com": (rng.normal(size=3) * 0.2).tolist(),
                    "inertia": [I[0, 0], I[0, 1], I[1, 1], I[0, 2], I[1, 2], I[2, 2]]})
    return out


def staubli_like(seed=0):
    return jflex.from_dh(STAUBLI_DH, tool=[0, 0.994, 0, 0], inertias=random_inertias(3, seed))


def arm_urdf(seed=0):
    rng = np.random.default_rng(seed)
    links = ['<link name="base"/>']
    joints = []
    origins = [("0 0 0.6", "0 0 0"), ("0.25 0 0", "1.5708 0 0"), ("0.9 0 0", "0 0 0")]
    parent = "base"
    for i, (xyz, rpy) in enumerate(origins):
        m = rng.uniform(2, 20)
        c = rng.normal(size=3) * 0.2
        I = _random_com_inertia(rng)
        links.append(
            f'<link name="l{i + 1}"><inertial><origin xyz="{c[0]} {c[1]} {c[2]}" rpy="0 0 0"/><mass value="{m}"/>'
            f'<inertia ixx="{I[0, 0]}" ixy="{I[0, 1]}" ixz="{I[0, 2]}" iyy="{I[1, 1]}" iyz="{I[1, 2]}" izz="{I[2, 2]}"/>'
            "</inertial></link>"
        )
        joints.append(
            f'<joint name="j{i + 1}" type="revolute"><parent link="{parent}"/><child link="l{i + 1}"/>'
            f'<origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="0 0 1"/>'
            '<limit lower="-3" upper="3" effort="100" velocity="3"/></joint>'
        )
        parent = f"l{i + 1}"
    return '<robot name="arm">' + "".join(links) + "".join(joints) + "</robot>"
