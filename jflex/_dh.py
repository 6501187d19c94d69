"""Robots from Denavit-Hartenberg tables (modified/Craig and standard conventions)."""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from ._errors import ConfigError
from ._robot import PRISMATIC, REVOLUTE, Robot, make_robot, move_params


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _T(R=np.eye(3), p=(0.0, 0.0, 0.0)):
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = p
    return T


def _Tx(a):
    return _T(p=(a, 0, 0))


def _Tz(d):
    return _T(p=(0, 0, d))


def dh_link_transform(alpha, a, d, theta, convention: str) -> np.ndarray:
    """The classical 4x4 transform of one DH row (for references and tool frames).

    modified (Craig): ``Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i)``;
    standard: ``Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``.
    """
    if convention == "modified":
        return _T(_rx(alpha)) @ _Tx(a) @ _T(_rz(theta)) @ _Tz(d)
    return _T(_rz(theta)) @ _Tz(d) @ _Tx(a) @ _T(_rx(alpha))


def _inertial_params(spec, where: str) -> np.ndarray:
    """10 parameters from ``{mass, com, inertia}`` (inertia about the com, 3x3 or
    [Ixx, Ixy, Iyy, Ixz, Iyz, Izz]) or ``{params: [10 numbers]}``."""
    if spec is None:
        return np.zeros(10)
    if isinstance(spec, Mapping):
        if "params" in spec:
            p = np.asarray(spec["params"], dtype=float)
            if p.shape != (10,):
                raise ConfigError(f"{where}.params: expected 10 numbers [m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz], got shape {p.shape}")
            return p
        if "mass" not in spec:
            raise ConfigError(f"{where}: expected 'mass' (and optional 'com', 'inertia') or 'params'")
        m = float(spec["mass"])
        c = np.asarray(spec.get("com", [0.0, 0.0, 0.0]), dtype=float)
        if c.shape != (3,):
            raise ConfigError(f"{where}.com: expected 3 numbers [m], got shape {c.shape}")
        I = np.asarray(spec.get("inertia", np.zeros(6)), dtype=float)
        if I.shape == (6,):
            I = np.array([[I[0], I[1], I[3]], [I[1], I[2], I[4]], [I[3], I[4], I[5]]])
        if I.shape != (3, 3):
            raise ConfigError(f"{where}.inertia: expected [Ixx, Ixy, Iyy, Ixz, Iyz, Izz] or 3x3 about the com, got shape {I.shape}")
        I_o = I + m * (c @ c * np.eye(3) - np.outer(c, c))
        h = m * c
        return np.array([m, *h, I_o[0, 0], I_o[0, 1], I_o[1, 1], I_o[0, 2], I_o[1, 2], I_o[2, 2]])
    p = np.asarray(spec, dtype=float)
    if p.shape != (10,):
        raise ConfigError(f"{where}: expected a mapping or 10 numbers, got shape {p.shape}")
    return p


def from_dh(
    table,
    *,
    convention: str = "modified",
    joint_types: Sequence[str] | None = None,
    tool=None,
    inertias: Sequence | None = None,
    gravity=(0.0, 0.0, -9.81),
    joint_names: Sequence[str] | None = None,
    lower=None,
    upper=None,
    velocity_limit=None,
    effort_limit=None,
) -> Robot:
    """Build a serial :class:`Robot` from a DH table.

    **Arguments:**

    - ``table``: (n, 4) rows ``[alpha, a, d, theta]`` [rad, m, m, rad]. In the ``"modified"``
      (Craig) convention row i holds ``alpha_{i-1}, a_{i-1}, d_i, theta_i`` as in Table 2.1 of the thesis "Posture Dependent Dynamics in Robotic Machining";
      in the ``"standard"`` convention ``alpha_i, a_i, d_i, theta_i``. For a revolute joint ``theta``
      is the offset added to ``q_i``; for a prismatic joint ``d`` is.
    - ``joint_types``: ``"revolute"``/``"prismatic"`` (or ``"R"``/``"P"``) per row; default revolute.
    - ``tool``: optional tool frame, a DH row ``[alpha, a, d, theta]`` (modified: the
      "end-effector" row of Table 2.2) or a 4x4 transform from the last link frame.
    - ``inertias``: per link ``{mass, com, inertia}`` (inertia about the com) or 10 parameters,
      all in that link's DH frame.

    Body frame i is the frame of joint i. In the modified convention that is the DH frame i. In
    the standard convention DH frame i sits at ``Tx(a_i) Rx(alpha_i)`` from it: inertias are moved
    to the body frame, and each DH frame is kept as a named frame ``dh<i>``.
    """
    if convention not in ("modified", "standard"):
        raise ConfigError(f"DH convention must be 'modified' (Craig) or 'standard', got '{convention}'")
    tab = np.asarray(table, dtype=float)
    if tab.ndim != 2 or tab.shape[1] != 4:
        raise ConfigError(
            f"DH table: expected n rows of 4 columns [alpha, a, d, theta], got shape {tab.shape}"
        )
    n = tab.shape[0]
    if n == 0:
        raise ConfigError("DH table: needs at least one row")
    if not np.isfinite(tab).all():
        raise ConfigError("DH table: contains NaN or inf")
    types = []
    for i, t in enumerate(joint_types or ["revolute"] * n):
        t = {"r": REVOLUTE, "p": PRISMATIC}.get(str(t).lower(), str(t).lower())
        if t not in (REVOLUTE, PRISMATIC):
            raise ConfigError(f"DH joint_types[{i}]: expected 'revolute'/'R' or 'prismatic'/'P', got '{t}'")
        types.append(t)
    if len(types) != n:
        raise ConfigError(f"DH joint_types: expected {n} entries (one per row), got {len(types)}")
    names = list(joint_names) if joint_names is not None else [f"joint{i + 1}" for i in range(n)]
    if len(names) != n:
        raise ConfigError(f"DH joint_names: expected {n} names, got {len(names)}")
    if inertias is not None and len(inertias) != n:
        raise ConfigError(f"DH inertias: expected {n} entries (one per link), got {len(inertias)}")

    Rs, ps, params = [], [], []
    frame_names, frame_parents, frame_T = [], [], []
    for i in range(n):
        alpha, a, d, theta = tab[i]
        joint_part = _T(_rz(theta)) @ _Tz(d)  # Rz and Tz commute: the joint variable goes last
        if convention == "modified":
            T = _T(_rx(alpha)) @ _Tx(a) @ joint_part
            body_from_dh = np.eye(4)
        else:
            prev = tab[i - 1] if i > 0 else None
            T = (_Tx(prev[1]) @ _T(_rx(prev[0])) if prev is not None else np.eye(4)) @ joint_part
            body_from_dh = _Tx(a) @ _T(_rx(alpha))
            frame_names.append(f"dh{i + 1}")
            frame_parents.append(i)
            frame_T.append(body_from_dh)
        Rs.append(T[:3, :3])
        ps.append(T[:3, 3])
        pi = _inertial_params(inertias[i] if inertias is not None else None, f"inertias[{i}]")
        params.append(move_params(pi, body_from_dh) if convention == "standard" else pi)

    if tool is not None:
        tool = np.asarray(tool, dtype=float)
        if tool.shape == (4,):
            Tt = dh_link_transform(*tool, convention)
            if convention == "standard":
                Tt = _Tx(tab[-1, 1]) @ _T(_rx(tab[-1, 0])) @ Tt
        elif tool.shape == (4, 4):
            Tt = (_Tx(tab[-1, 1]) @ _T(_rx(tab[-1, 0])) @ tool) if convention == "standard" else tool
        else:
            raise ConfigError(f"DH tool: expected a DH row of 4 numbers or a 4x4 transform, got shape {tool.shape}")
        frame_names.append("tool")
        frame_parents.append(n - 1)
        frame_T.append(Tt)

    return make_robot(
        joint_names=names,
        link_names=[f"link{i + 1}" for i in range(n)],
        parents=list(range(-1, n - 1)),
        joint_types=types,
        placement_R=np.stack(Rs),
        placement_p=np.stack(ps),
        axis=np.tile([0.0, 0.0, 1.0], (n, 1)),
        inertia=np.stack(params),
        gravity=gravity,
        lower=lower,
        upper=upper,
        velocity_limit=velocity_limit,
        effort_limit=effort_limit,
        frame_names=frame_names,
        frame_parents=frame_parents,
        frame_R=np.stack([T[:3, :3] for T in frame_T]) if frame_T else None,
        frame_p=np.stack([T[:3, 3] for T in frame_T]) if frame_T else None,
    )
