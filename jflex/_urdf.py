"""Robots from URDF files: joints, limits and inertials; fixed joints merged into their parent
body (what they carried stays reachable as a named frame, e.g. a tool flange).

The result matches ``pinocchio.buildModelFromUrdf(path, mimic=True)`` (fixed base; mimic joints
as coupled coordinates, or with ``mimic="independent"`` as ``mimic=False``): the same joint order,
the same merged bodies and, for every URDF that ships in example-robot-data, the same ``rnea``,
``crba``, forward dynamics, kinematics and Jacobians (tests/test_urdf_parity.py). ``lock``/``joints`` reduce the model
as ``pinocchio.buildReducedModel`` does.
"""

from __future__ import annotations

import os
import pathlib
import warnings
import xml.etree.ElementTree as ET
from typing import Mapping, Sequence

import numpy as np

from ._errors import ParameterError, URDFError
from ._robot import PRISMATIC, REVOLUTE, Robot, inertia_defect, make_robot, move_params
from ._spatial import rot_axis_angle

_MOVING = {"revolute": REVOLUTE, "continuous": REVOLUTE, "prismatic": PRISMATIC}
_FREE = ("floating", "planar")
_SUPPORTED = tuple(_MOVING) + ("fixed",) + _FREE


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


def _link_inertia(link, fname, strict):
    """10 parameters of a <link> in its own frame (zeros if it has no <inertial>).

    Point masses and massless links are accepted, as Pinocchio accepts them. A non-physical
    inertia (not positive semi-definite beyond round-off, or breaking the triangle inequality) is
    loaded as given with a warning naming the link, or refused when ``strict``."""
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
    if not np.isfinite(I).all():
        raise URDFError(f"{where}: <inertia> contains inf")
    T = _origin(inertial, f"{where} <inertial>")
    R, c = T[:3, :3], T[:3, 3]
    I_c = R @ I @ R.T
    I_o = I_c + m * (c @ c * np.eye(3) - np.outer(c, c))
    h = m * c
    pi = np.array([m, *h, I_o[0, 0], I_o[0, 1], I_o[1, 1], I_o[0, 2], I_o[1, 2], I_o[2, 2]])
    defect = inertia_defect(pi)
    if defect is not None:
        if strict:
            raise URDFError(f"{where}: non-physical inertia: {defect} (strict=True refuses it)")
        warnings.warn(
            f"{where}: non-physical inertia loaded as given, as Pinocchio loads it: {defect}. "
            "An identification can correct it; load_urdf(..., strict=True) refuses it.",
            UserWarning,
            stacklevel=4,
        )
    return pi


def load_urdf(
    path: str | os.PathLike,
    *,
    gravity=(0.0, 0.0, -9.81),
    lock: Mapping[str, float] | None = None,
    joints: Sequence[str] | None = None,
    mimic: str = "coupled",
    floating: str | None = None,
    strict: bool = False,
) -> Robot:
    """Load a URDF into a fixed-base :class:`Robot`.

    Revolute, continuous and prismatic joints become joints, in Pinocchio's order: depth first
    from the root, a link's children in the order of their joint names (urdfdom keeps joints in a
    sorted map). A continuous joint is a revolute joint without limits, its coordinate the angle
    (Pinocchio stores it as ``(cos, sin)``). Fixed joints are merged into the parent body, their
    child links kept as named frames. The root link is fixed to the world, as in
    ``pinocchio.buildModelFromUrdf(path)`` without a root joint: a legged robot or humanoid loads
    with its base held where it stands.

    **Arguments:**

    - ``lock``: ``{joint name: value}`` [rad or m]: these joints become fixed joints at that value,
      their links merged into the parent body (``pinocchio.buildReducedModel``).
    - ``joints``: the joints to keep (each once); every other moving joint is locked at its
      ``lock`` value, or 0 (a joint that mimics a locked joint: at ``multiplier * value + offset``;
      one that mimics a kept joint stays coupled to it).
    - ``mimic``: what to do with a joint whose ``<mimic joint multiplier offset>`` couples it to
      a leader. ``"coupled"`` (default): it moves at ``multiplier * q_leader + offset`` and has no
      coordinate of its own, as ``pinocchio.buildModelFromUrdf(path, mimic=True)`` models it
      (``robot.nq`` counts the coordinates, ``robot.coordinate_names`` names them, while
      ``robot.joint_names`` lists every joint of the tree); a joint that mimics a locked joint is
      locked with it. ``"independent"`` loads it as an independent joint, as
      ``pinocchio.buildModelFromUrdf(path)`` does by default; ``"refuse"`` raises for a kept one.
    - ``floating``: what to do with a ``floating`` or ``planar`` joint from the root link (a
      floating base written as a joint from ``world``): ``"fixed"`` welds it at its origin
      (the default, with a warning unless passed explicitly), ``"refuse"`` raises. Such joints
      deeper in the tree are refused.
    - ``strict``: refuse non-physical link inertias (by default they load with a warning naming the
      link, as Pinocchio loads them; an identification can correct them). Point masses, massless
      links and round-off relative to the link's own scale are physical.

    Errors (a :class:`URDFError`) name the file and the link, joint or argument at fault.
    """
    path = pathlib.Path(path)
    fname = str(path)
    if not path.is_file():
        raise URDFError(f"{fname}: URDF file not found")
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise URDFError(f"{fname}: not valid XML ({exc})") from None
    return _from_element(root, fname, gravity, lock, joints, mimic, floating, strict)


def from_urdf_string(
    text: str,
    *,
    gravity=(0.0, 0.0, -9.81),
    name: str = "<string>",
    lock: Mapping[str, float] | None = None,
    joints: Sequence[str] | None = None,
    mimic: str = "coupled",
    floating: str | None = None,
    strict: bool = False,
) -> Robot:
    """Like :func:`load_urdf`, from the XML text itself (``name`` stands for the file in errors)."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise URDFError(f"{name}: not valid XML ({exc})") from None
    return _from_element(root, name, gravity, lock, joints, mimic, floating, strict)


def _parse_tree(root, fname):
    """Links by name, joints by name, children (joint elements) per link, the root link."""
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
    parent_of, by_name = {}, {}
    for j in root.findall("joint"):
        jname = j.get("name")
        where = f"{fname}: joint '{jname}'"
        if not jname:
            raise URDFError(f"{fname}: a <joint> has no name")
        if jname in by_name:
            raise URDFError(f"{where} is defined twice; joint names must be unique")
        jtype = j.get("type")
        if jtype not in _SUPPORTED:
            raise URDFError(
                f"{where}: unknown or unsupported joint type '{jtype}'; jflex models fixed-base trees "
                f"with joint types {list(_SUPPORTED[:4])}"
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
        by_name[jname] = j
        children[parent].append(j)
    roots = [k for k in links if k not in parent_of]
    if len(roots) != 1:
        raise URDFError(f"{fname}: expected exactly one root link, found {roots or 'none (a cycle)'}")
    # every link has one parent, so a link not below the root lies on (or hangs from) a cycle of
    # joints; the walk from the root would drop it, and its joints, without a word
    reached, stack = {roots[0]}, [roots[0]]
    while stack:
        for j in children[stack.pop()]:
            c = j.find("child").get("link")
            if c not in reached:
                reached.add(c)
                stack.append(c)
    cut = [k for k in links if k not in reached]
    if cut:
        lost = [j.get("name") for j in root.findall("joint") if j.find("child").get("link") in cut]
        raise URDFError(f"{fname}: links {cut} are not reached from the root link '{roots[0]}' (their joints {lost} "
                        "form a cycle); expected a tree: every link below the root through one chain of joints")
    # urdfdom keeps joints in a map sorted by name, so Pinocchio visits a link's children in the
    # order of their joint names (not file order); the joint order of the model follows.
    for lst in children.values():
        lst.sort(key=lambda j: j.get("name"))
    return links, by_name, children, roots[0]


def _mimic_of(j, by_name, where):
    """(leader, multiplier, offset) of a moving joint's <mimic>, or None."""
    el = j.find("mimic")
    if el is None:
        return None
    leader = el.get("joint")
    if leader not in by_name or by_name[leader].get("type") not in _MOVING:
        raise URDFError(
            f"{where}: <mimic joint='{leader}'> must name a revolute, continuous or prismatic joint of this URDF; "
            "mimic='independent' ignores <mimic> (as pinocchio.buildModelFromUrdf(path) does)"
        )
    a, b = _attr_float(el, "multiplier", f"{where} <mimic>", 1.0), _attr_float(el, "offset", f"{where} <mimic>", 0.0)
    if not (np.isfinite(a) and np.isfinite(b)):
        raise URDFError(f"{where} <mimic>: multiplier and offset must be finite, got {a} and {b}")
    return leader, a, b


_MIMIC_MODES = ("coupled", "independent", "refuse")


def _resolved_mimics(fname, by_name, moving):
    """{follower: (leader, multiplier, offset)} with every leader an independent joint: a chain
    (a mimics b mimics c) composes to ``q_a = a_ab a_bc q_c + (a_ab b_bc + b_ab)``."""
    direct = {}
    for k in moving:
        m = _mimic_of(by_name[k], by_name, f"{fname}: joint '{k}'")
        if m is not None:
            direct[k] = m
    out = {}
    for k in direct:
        a, b, lead, seen = 1.0, 0.0, k, [k]
        while lead in direct:
            lead, ak, bk = direct[lead]
            a, b = a * ak, a * bk + b
            if lead in seen:
                raise URDFError(f"{fname}: joints {seen} mimic each other in a cycle")
            seen.append(lead)
        out[k] = (lead, a, b)
    return out


def _locked_values(fname, by_name, lock, joints, mimic):
    """``({joint name: value}, {follower: (leader, multiplier, offset)})``: the moving joints that
    become fixed (``lock``/``joints``/``mimic``) and the kept joints that mimic a kept leader."""
    if not isinstance(mimic, str) or mimic not in _MIMIC_MODES:
        raise URDFError(f"{fname}: mimic must be one of {list(_MIMIC_MODES)}, got {mimic!r}")
    moving = [k for k, j in by_name.items() if j.get("type") in _MOVING]
    lock = {} if lock is None else lock
    if not isinstance(lock, Mapping):
        raise URDFError(f"{fname}: lock must be a mapping {{joint name: value}}, got {type(lock).__name__}")

    def known(name, arg):
        if name not in by_name or name not in moving:
            what = "is not a moving joint" if name in by_name else "is not a joint"
            raise URDFError(f"{fname}: {arg} names '{name}', which {what} of this URDF; moving joints: {moving}")

    values = {}
    for name, v in lock.items():
        known(name, "lock")
        try:
            x = float(v)
        except (TypeError, ValueError):
            raise URDFError(f"{fname}: lock['{name}'] must be a number [rad or m], got {v!r}") from None
        if not np.isfinite(x):
            raise URDFError(f"{fname}: lock['{name}'] must be finite, got {v!r}")
        lim = by_name[name].find("limit")
        if by_name[name].get("type") != "continuous" and lim is not None:
            lo = _attr_float(lim, "lower", f"{fname}: joint '{name}' <limit>", 0.0)
            hi = _attr_float(lim, "upper", f"{fname}: joint '{name}' <limit>", 0.0)
            if not lo <= x <= hi:
                raise URDFError(f"{fname}: lock['{name}'] = {x} lies outside the joint's limits [{lo}, {hi}]")
        values[name] = x
    keep = set(moving)
    named = set()
    if joints is not None:
        if isinstance(joints, str) or not all(isinstance(k, str) for k in joints):
            raise URDFError(f"{fname}: joints must be a list of joint names, got {joints!r}")
        for name in joints:
            known(name, "joints")
            if name in named:
                raise URDFError(f"{fname}: joints names '{name}' twice; each joint once")
            named.add(name)
            if name in values:
                raise URDFError(f"{fname}: joint '{name}' is both kept (joints) and locked (lock)")
        keep = set(named)
    keep -= set(values)
    # 'independent' ignores <mimic> as Pinocchio does by default (it may even name a missing joint)
    mimics = {} if mimic == "independent" else _resolved_mimics(fname, by_name, moving)
    coupled = {}
    for name in moving:
        if name not in mimics or name in values:
            continue
        leader, a, b = mimics[name]
        if leader in keep:
            # a follower moves with its kept leader (named in joints or not: it has no coordinate)
            coupled[name] = mimics[name]
            keep.add(name)
        elif name in named and mimic == "coupled":
            raise URDFError(
                f"{fname}: joints names '{name}', which mimics joint '{leader}' (multiplier {a}, offset {b}) and has "
                f"no coordinate of its own; '{leader}' is locked: keep '{leader}', or leave '{name}' out (it is then "
                "locked with its leader)"
            )
        elif name not in named:
            # a joint that mimics a locked joint, and is not named itself, follows its leader's value
            values[name] = a * values.get(leader, 0.0) + b
            keep.discard(name)
    for name in moving:
        if name not in keep:
            values.setdefault(name, 0.0)
    for name, (leader, a, b) in mimics.items():
        if name in values and leader in values:
            continue
        if name in values or mimic == "refuse":  # locked while its leader moves, or kept coupled
            raise URDFError(
                f"{fname}: joint '{name}' mimics joint '{leader}' (multiplier {a}, offset {b})"
                + (" but is locked while its leader moves: the coupling would break. " if name in values else
                   " and mimic='refuse'. ")
                + f"Lock both (lock={{'{leader}': 0.0}} locks '{name}' with it), load them coupled with "
                "mimic='coupled' (the default, as pinocchio.buildModelFromUrdf(path, mimic=True)), or as "
                "independent joints with mimic='independent' (Pinocchio's default)"
            )
    return values, coupled


def _warn_massless(fname, inertia, joint_names, link_names, parents) -> None:
    """Warn, naming the link, of a moving body without mass or inertia (its fixed children merged
    in). Such a link is legal (a frame on a joint: Pinocchio loads it), so it is not refused; but
    when nothing below its joint has mass either, the model gives that joint no inertial torque at
    all, and a measured torque there reads as a wrong torque scale or a missing effect."""
    n = len(joint_names)
    empty = [not np.any(np.asarray(inertia[i])) for i in range(n)]
    carried = list(empty)  # True: nothing at or below body i has mass
    for i in reversed(range(n)):  # parents precede their children
        if not carried[i] and parents[i] >= 0:
            carried[parents[i]] = False
    for i in range(n):
        if empty[i]:
            warnings.warn(
                f"{fname}: link '{link_names[i]}' (moved by joint '{joint_names[i]}') has zero mass and inertia"
                + (f"; nothing below joint '{joint_names[i]}' has mass, so the model gives it no inertial torque "
                   "(expected the link's <inertial>, unless the joint moves only a frame)" if carried[i] else
                   " (a frame on a joint is legal; a real link needs its <inertial>)"),
                UserWarning, stacklevel=4)


def _from_element(root, fname, gravity, lock=None, joints=None, mimic="coupled", floating=None, strict=False) -> Robot:
    links, by_name, children, root_link = _parse_tree(root, fname)
    if floating not in (None, "fixed", "refuse"):
        raise URDFError(f"{fname}: floating must be 'fixed' or 'refuse', got {floating!r}")
    locked, coupled = _locked_values(fname, by_name, lock, joints, mimic)

    # Depth-first walk. Each URDF link maps to (body index or -1 for the base, T link->body).
    joint_names, link_names, parents, types = [], [], [], []
    Rs, ps, axes, inertia, lims = [], [], [], [], []
    frame_names, frame_parents, frame_T = [], [], []
    base_params = np.zeros(10)

    def axis_of(j, where):
        axis_el = j.find("axis")
        axis = _floats(axis_el.get("xyz"), 3, f"{where} <axis xyz>") if axis_el is not None else np.array([1.0, 0, 0])
        if np.linalg.norm(axis) == 0:
            raise URDFError(f"{where}: <axis xyz> must be non-zero")
        return axis / np.linalg.norm(axis)

    def attach(child, j, body, T_body_joint):
        """(body, T body->child link) for the link ``child`` reached from ``body`` through joint j
        (origin applied): a new body for a moving joint, else the parent's body and a frame."""
        jname = j.get("name")
        where = f"{fname}: joint '{jname}'"
        jtype = j.get("type")
        if jtype in _FREE:
            if body >= 0 or j.find("parent").get("link") != root_link:
                raise URDFError(
                    f"{where}: unknown or unsupported joint type '{jtype}' below the root link; jflex models "
                    "fixed-base trees (a free joint from the root link, a floating base, is welded there)"
                )
            if floating == "refuse":
                raise URDFError(
                    f"{where}: a {jtype} joint from the root link (a floating base) and floating='refuse'; "
                    "jflex models fixed-base trees: floating='fixed' welds it at its origin"
                )
            if floating is None:
                warnings.warn(
                    f"{where}: {jtype} joint from the root link welded at its origin: jflex models "
                    "fixed-base trees (pass floating='fixed' to say so, or 'refuse')",
                    UserWarning,
                    stacklevel=4,
                )
        if jtype in _FREE or jtype == "fixed" or jname in locked:
            if jname in locked:
                T_motion = np.eye(4)
                axis, v = axis_of(j, where), locked[jname]
                if jtype == "prismatic":
                    T_motion[:3, 3] = axis * v
                else:
                    T_motion[:3, :3] = rot_axis_angle(np.asarray(axis, float), float(v), np)
                T_body_joint = T_body_joint @ T_motion
            frame_names.append(child)
            frame_parents.append(body)
            frame_T.append(T_body_joint)
            return body, T_body_joint
        axis = axis_of(j, where)
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
        axes.append(axis)
        inertia.append(np.zeros(10))
        lims.append((lo, hi, vel, eff))
        return idx, np.eye(4)

    # Depth first, with an explicit stack (a long chain must not exhaust Python's recursion
    # limit): each entry is a link reached through joint j (None for the root) from ``body``, whose
    # frame sits at T_body_link once j's own motion is applied.
    stack = [(root_link, None, -1, np.eye(4))]
    while stack:
        link_name, j, body, T_body_link = stack.pop()
        if j is not None:
            body, T_body_link = attach(link_name, j, body, T_body_link)
        pi = move_params(_link_inertia(links[link_name], fname, strict), T_body_link)
        if body < 0:
            base_params = base_params + pi
        else:
            inertia[body] = inertia[body] + pi
        # reversed: the first child (in joint-name order) comes off the stack first
        for jc in reversed(children[link_name]):
            stack.append((jc.find("child").get("link"), jc, body, T_body_link @ _origin(jc, f"{fname}: joint '{jc.get('name')}'")))
    if not joint_names:
        raise URDFError(
            f"{fname}: no moving joints (revolute, continuous or prismatic)" + (" left after lock/joints" if locked else "")
        )
    _warn_massless(fname, inertia, joint_names, link_names, parents)
    lims = np.array(lims)
    try:
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
            base_name=root_link,
            mimic=[(k, *coupled[k]) for k in joint_names if k in coupled],
            check_physical=False,  # each link was checked above, by name (a sum of physical bodies is physical)
        )
    except ParameterError as exc:
        raise URDFError(f"{fname}: {exc}") from None
