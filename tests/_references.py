"""Independent references shared by the tests: Pinocchio models and classical DH products."""

from __future__ import annotations

import numpy as np

try:
    import pinocchio as pin
except ImportError:  # the test extra is missing: tests that need it skip
    pin = None


def pin_model_from_robot(robot):
    """A Pinocchio model with the same joints, placements, axes and inertias as ``robot``."""
    model = pin.Model()
    model.gravity = pin.Motion(np.asarray(robot.gravity), np.zeros(3))
    ids = []
    for i in range(robot.nq):
        parent = 0 if robot.parents[i] < 0 else ids[robot.parents[i]]
        axis = np.asarray(robot.axis[i])
        if robot.joint_types[i] == "revolute":
            jm = pin.JointModelRevoluteUnaligned(axis)
        else:
            jm = pin.JointModelPrismaticUnaligned(axis)
        placement = pin.SE3(np.asarray(robot.placement_R[i]), np.asarray(robot.placement_p[i]))
        jid = model.addJoint(parent, jm, placement, robot.joint_names[i])
        pi = np.asarray(robot.inertia[i])
        model.appendBodyToJoint(jid, pin.Inertia.FromDynamicParameters(pi), pin.SE3.Identity())
        ids.append(jid)
    return model


def random_inertia_params(rng):
    """Physically valid 10 parameters: positive mass, com, PD inertia obeying the triangle inequality."""
    m = rng.uniform(0.5, 10.0)
    c = rng.uniform(-0.3, 0.3, 3)
    d = rng.uniform(0.05, 1.0, 3)
    # principal moments from a random solid box: always satisfy the triangle inequality
    a, b, cc = d
    Ip = m / 12.0 * np.array([b * b + cc * cc, a * a + cc * cc, a * a + b * b])
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    I_c = Q @ np.diag(Ip) @ Q.T
    I_o = I_c + m * (c @ c * np.eye(3) - np.outer(c, c))
    h = m * c
    return np.array([m, *h, I_o[0, 0], I_o[0, 1], I_o[1, 1], I_o[0, 2], I_o[1, 2], I_o[2, 2]])


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    T = np.eye(4)
    T[1:3, 1:3] = [[c, -s], [s, c]]
    return T


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    T = np.eye(4)
    T[0:2, 0:2] = [[c, -s], [s, c]]
    return T


def _tr(x, z):
    T = np.eye(4)
    T[0, 3], T[2, 3] = x, z
    return T


def dh_chain(table, q, types, convention):
    """Textbook DH product: list of 4x4 DH frames for joint values ``q``."""
    T = np.eye(4)
    frames = []
    for (alpha, a, d, theta), qi, t in zip(table, q, types):
        th = theta + (qi if t == "revolute" else 0.0)
        dd = d + (qi if t == "prismatic" else 0.0)
        if convention == "modified":
            T = T @ _rx(alpha) @ _tr(a, 0) @ _rz(th) @ _tr(0, dd)
        else:
            T = T @ _rz(th) @ _tr(0, dd) @ _tr(a, 0) @ _rx(alpha)
        frames.append(T.copy())
    return frames


def fe_beam_matrices(L, m, EI, ne=60):
    """Independent beam reference: stiffness and mass matrices of a uniform Euler-Bernoulli beam
    from ``ne`` Hermite cubic elements, dofs (w, w') per node from the root; nothing clamped."""
    h = L / ne
    ke = EI / h**3 * np.array([[12, 6 * h, -12, 6 * h], [6 * h, 4 * h * h, -6 * h, 2 * h * h],
                               [-12, -6 * h, 12, -6 * h], [6 * h, 2 * h * h, -6 * h, 4 * h * h]])
    me = m * h / 420 * np.array([[156, 22 * h, 54, -13 * h], [22 * h, 4 * h * h, 13 * h, -3 * h * h],
                                 [54, 13 * h, 156, -22 * h], [-13 * h, -3 * h * h, -22 * h, 4 * h * h]])
    n = 2 * (ne + 1)
    K, M = np.zeros((n, n)), np.zeros((n, n))
    for e in range(ne):
        i = slice(2 * e, 2 * e + 4)
        K[i, i] += ke
        M[i, i] += me
    return K, M


def light_system(n, seed):
    """A random n-DOF M, C, K with non-proportional damping of a few % (underdamped modes)."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    M = A @ A.T + n * np.eye(n)
    B = rng.normal(size=(n, n))
    K = 100.0 * (B @ B.T + n * np.eye(n))
    D = rng.normal(size=(n, n))
    C = 0.02 * (D @ D.T) + 1e-3 * K
    return M, C, K
