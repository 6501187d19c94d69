"""Robots from URDF files: joints, limits and inertials; fixed joints merged into their parent
body (what they carried stays reachable as a named frame, e.g. a tool flange)."""

from __future__ import annotations

import os
import pathlib
import xml.etree.ElementTree as ET

import numpy as np

from ._errors import URDFError
from ._robot import PRISMATIC, REVOLUTE, Robot, check_inertia, make_robot, move_params
from ._errors import ParameterError

_MOVING = {"revolute": REVOLUTE, "continuous": REVOLUTE, "prismatic": PRISMATIC}
_SUPPORTED = tuple(_MOVING) + ("fixed",)


def _rpy(r, p, y):
    cr, sr, cp, sp_, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp_], [0, 1, 0], [-sp_, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def _floats(text, n, where):
    try:
        vals = [float(v) for v in (text or "").split()]
    except ValueError:
        raise URDFError(f"{where}: expected {n} numbers, got '{text}'") from None
    if len(vals) != n:
        raise URDFError(f"{where}: expected {n} numbers, got '{text}'")
    if not np.isfinite(vals).all():
        raise URDFError(f"{where}: contains NaN or inf: '{text}'")
    return np.array(vals)


def _origin(el, where):
    T = np.eye(4)
    o = el.find("origin") if el is not None else None
    if o is not None:
        xyz = _floats(o.get("xyz", "0 0 0"), 3, f"{where} <origin xyz>")
        rpy = _floats(o.get("rpy", "0 0 0"), 3, f"{where} <origin rpy>")
        T[:3, :3] = _rpy(*rpy)
        T[:3, 3] = xyz
    return T


def _attr_float(el, name, where, default=None):
    v = el.get(name) if el is not None else None
    if v is None:
        if default is None:
            raise URDFError(f"{where}: missing attribute '{name}'")
        return default
    try:
        x = float(v)
    except ValueError:
        raise URDFError(f"{where}: attribute '{name}' must be a number, got '{v}'") from None
    if np.isnan(x):
        raise URDFError(f"{where}: attribute '{name}' must be a number, got '{v}'")
    return x


def _link_inertia(link, fname):
    """10 parameters of a <link> in its own frame (zeros if it has no <inertial>)."""
    name = link.get("name")
    where = f"{fname}: link '{name}'"
    inertial = link.find("inertial")
    if inertial is None:
        return np.zeros(10)
    mass_el = inertial.find("mass")
    if mass_el is None:
        raise URDFError(f"{where}: <inertial> has no <mass>")
    m = _attr_float(mass_el, "value", f"{where} <mass>")
    if not m >= 0:
        raise URDFError(f"{where}: mass must be >= 0, got {m}")
    I_el = inertial.find("inertia")
    if I_el is None:
        raise URDFError(f"{where}: <inertial> has no <inertia> (ixx ixy ixz iyy iyz izz about the centre of mass)")
    vals = {k: _attr_float(I_el, k, f"{where} <inertia>") for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
    I = np.array(
        [[vals["ixx"], vals["ixy"], vals["ixz"]], [vals["ixy"], vals["iyy"], vals["iyz"]], [vals["ixz"], vals["iyz"], vals["izz"]]]
    )
    T = _origin(inertial, f"{where} <inertial>")
    R, c = T[:3, :3], T[:3, 3]
    I_c = R @ I @ R.T
    ev = np.linalg.eigvalsh(I_c)
    if m > 0 and ev.min() <= 0:
        raise URDFError(f"{where}: inertia is not positive definite (principal moments {ev.tolist()})")
    I_o = I_c + m * (c @ c * np.eye(3) - np.outer(c, c))
    h = m * c
    pi = np.array([m, *h, I_o[0, 0], I_o[0, 1], I_o[1, 1], I_o[0, 2], I_o[1, 2], I_o[2, 2]])
    try:
        check_inertia(pi, where)
    except ParameterError as exc:
        raise URDFError(str(exc)) from None
    return pi


def load_urdf(path: str | os.PathLike, *, gravity=(0.0, 0.0, -9.81)) -> Robot:
    """Load a fixed-base URDF into a :class:`Robot`.

    Revolute, continuous and prismatic joints become joints (in depth-first order from the root,
    children in file order, as Pinocchio orders them); fixed joints are merged into the parent body,
    their child links kept as named frames. Errors name the file, link or joint at fault.
    """
    path = pathlib.Path(path)
    fname = str(path)
    if not path.is_file():
        raise URDFError(f"{fname}: URDF file not found")
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise URDFError(f"{fname}: not valid XML ({exc})") from None
    return _from_element(root, fname, gravity)


def from_urdf_string(text: str, *, gravity=(0.0, 0.0, -9.81), name: str = "<string>") -> Robot:
    """Like :func:`load_urdf`, from the XML text itself."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise URDFError(f"{name}: not valid XML ({exc})") from None
    return _from_element(root, name, gravity)


def _from_element(root, fname, gravity) -> Robot:
    if root.tag != "robot":
        raise URDFError(f"{fname}: top element must be <robot>, got <{root.tag}>")
    links = {}
    for link in root.findall("link"):
        name = link.get("name")
        if not name:
            raise URDFError(f"{fname}: a <link> has no name")
        if name in links:
            raise URDFError(f"{fname}: link '{name}' is defined twice")
        links[name] = link
    if not links:
        raise URDFError(f"{fname}: no <link> elements")
    children: dict[str, list] = {k: [] for k in links}
    parent_of = {}
    for j in root.findall("joint"):
        jname = j.get("name")
        where = f"{fname}: joint '{jname}'"
        if not jname:
            raise URDFError(f"{fname}: a <joint> has no name")
        jtype = j.get("type")
        if jtype not in _SUPPORTED:
            raise URDFError(
                f"{where}: unknown or unsupported joint type '{jtype}'; jflex models fixed-base trees "
                f"with joint types {list(_SUPPORTED)}"
            )
        pel, cel = j.find("parent"), j.find("child")
        if pel is None or cel is None:
            raise URDFError(f"{where}: needs <parent link=...> and <child link=...>")
        parent, child = pel.get("link"), cel.get("link")
        if parent not in links:
            raise URDFError(f"{where}: parent link '{parent}' is not defined (dangling parent)")
        if child not in links:
            raise URDFError(f"{where}: child link '{child}' is not defined")
        if child in parent_of:
            raise URDFError(f"{where}: link '{child}' already has parent joint '{parent_of[child].get('name')}'")
        parent_of[child] = j
        children[parent].append(j)
    roots = [k for k in links if k not in parent_of]
    if len(roots) != 1:
        raise URDFError(f"{fname}: expected exactly one root link, found {roots or 'none (a cycle)'}")

    # Depth-first walk. Each URDF link maps to (body index or -1 for the base, T link->body).
    joint_names, link_names, parents, types = [], [], [], []
    Rs, ps, axes, inertia, lims = [], [], [], [], []
    frame_names, frame_parents, frame_T = [], [], []
    base_params = np.zeros(10)

    def visit(link_name, body, T_body_link):
        nonlocal base_params
        pi = move_params(_link_inertia(links[link_name], fname), T_body_link)
        if body < 0:
            base_params = base_params + pi
        else:
            inertia[body] = inertia[body] + pi
        for j in children[link_name]:
            jname = j.get("name")
            where = f"{fname}: joint '{jname}'"
            child = j.find("child").get("link")
            T_link_joint = _origin(j, where)
            T_body_joint = T_body_link @ T_link_joint
            jtype = j.get("type")
            if jtype == "fixed":
                frame_names.append(child)
                frame_parents.append(body)
                frame_T.append(T_body_joint)
                visit(child, body, T_body_joint)
                continue
            axis_el = j.find("axis")
            axis = _floats(axis_el.get("xyz"), 3, f"{where} <axis xyz>") if axis_el is not None else np.array([1.0, 0, 0])
            if np.linalg.norm(axis) == 0:
                raise URDFError(f"{where}: <axis xyz> must be non-zero")
            lim = j.find("limit")
            if jtype in ("revolute", "prismatic") and lim is None:
                raise URDFError(f"{where}: a {jtype} joint needs a <limit lower upper effort velocity>")
            if jtype == "continuous":
                lo, hi = -np.inf, np.inf
            else:
                lo = _attr_float(lim, "lower", f"{where} <limit>", 0.0)
                hi = _attr_float(lim, "upper", f"{where} <limit>", 0.0)
                if lo > hi:
                    raise URDFError(f"{where}: <limit> lower {lo} > upper {hi}")
            eff = _attr_float(lim, "effort", f"{where} <limit>", np.inf) if lim is not None else np.inf
            vel = _attr_float(lim, "velocity", f"{where} <limit>", np.inf) if lim is not None else np.inf
            idx = len(joint_names)
            joint_names.append(jname)
            link_names.append(child)
            parents.append(body)
            types.append(_MOVING[jtype])
            Rs.append(T_body_joint[:3, :3])
            ps.append(T_body_joint[:3, 3])
            axes.append(axis / np.linalg.norm(axis))
            inertia.append(np.zeros(10))
            lims.append((lo, hi, vel, eff))
            visit(child, idx, np.eye(4))

    visit(roots[0], -1, np.eye(4))
    if not joint_names:
        raise URDFError(f"{fname}: no moving joints (revolute, continuous or prismatic)")
    for i, pi in enumerate(inertia):
        try:
            check_inertia(pi, f"{fname}: link '{link_names[i]}' (with merged fixed children)")
        except ParameterError as exc:
            raise URDFError(str(exc)) from None
    lims = np.array(lims)
    try:
        return _make(fname, joint_names, link_names, parents, types, Rs, ps, axes, inertia, gravity, lims,
                     frame_names, frame_parents, frame_T, roots[0])
    except ParameterError as exc:
        raise URDFError(f"{fname}: {exc}") from None


def _make(fname, joint_names, link_names, parents, types, Rs, ps, axes, inertia, gravity, lims,
          frame_names, frame_parents, frame_T, base_name):
    return make_robot(
        joint_names=joint_names,
        link_names=link_names,
        parents=parents,
        joint_types=types,
        placement_R=np.stack(Rs),
        placement_p=np.stack(ps),
        axis=np.stack(axes),
        inertia=np.stack(inertia),
        gravity=gravity,
        lower=lims[:, 0],
        upper=lims[:, 1],
        velocity_limit=lims[:, 2],
        effort_limit=lims[:, 3],
        frame_names=frame_names,
        frame_parents=frame_parents,
        frame_R=np.stack([T[:3, :3] for T in frame_T]) if frame_T else None,
        frame_p=np.stack([T[:3, 3] for T in frame_T]) if frame_T else None,
        base_name=base_name,
    )
