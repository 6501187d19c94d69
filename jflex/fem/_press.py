"""The high-speed multi-link press (its Fig. 1) of the paper "Elastic dynamic research of high-speed multi-link precision press considering structural stiffness of rotation joints"
(the press paper below) as a linkage and as a finite-element model.

Topology (right side; the left side mirrors it about the slider axis x = 0)::

    crank L1 (O -> B)  --pin B--  rod L2 (B -> C1)  --pin C1--  deputy slider m1 (vertical guide)
    m1 --pin D--  toggle L3 (D -> S)  --pin S--  rocker = oscillating arm L6 (S -> Q) + upper link L4 (Q -> A)
    rocker --frame pin A--   rocker --pin Q--  lower link L5 (Q -> M)  --pin M--  main slider m2

The press paper's text connects L4 to L6 by a pin; with that pin the frame-L4-L6-L3-m1 loop is a
four-bar whose coupler L6 keeps a free degree of freedom, which a press cannot have. L4 and L6
are therefore taken as one rigid rocker (welded at Q): L4 carries the press load from Q to the
frame pin A, L6 is the arm the toggle drives. At BDC the knee Q lies straight below A
and the rocker is at the end of its swing; the slider pins sit a little outside
(``main_half_width``), so the toggle A-Q-M stops short of straight: the slider dwells near BDC
but still decelerates (a toggle straight at the rocker's reversal would make the slider's
acceleration vanish at BDC).

Loop-closure unknowns ``q = [th2, y1, th3R, psiR, th5R, y2R, th3L, psiL, th5L, y2L]``: rod angle,
deputy-slider height, and per side the toggle angle, rocker rotation from its BDC pose, lower-link
angle and slider-pin height. The crank angle ``phi`` puts the crank pin at ``O - r (cos phi, sin phi)``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._errors import ConfigError
from ._assembly import FEModel, fe_model
from ._linkage import LinkageMotion, linkage_motion, point_motion

POINTS = ("O", "B", "C1", "DL", "DR", "SL", "SR", "AL", "AR", "QL", "QR", "ML", "MR", "C2")
_P = {p: k for k, p in enumerate(POINTS)}

# (member, start point, end point, body, section)
MEMBERS = (
    ("L1", "O", "B", "crank", "crank"),
    ("L2", "B", "C1", "rod", "rod"),
    ("m1L", "C1", "DL", "m1", "deputy"),
    ("m1R", "C1", "DR", "m1", "deputy"),
    ("L3L", "DL", "SL", "L3L", "toggle"),
    ("L3R", "DR", "SR", "L3R", "toggle"),
    ("L6L", "SL", "QL", "rockerL", "oscillating"),
    ("L6R", "SR", "QR", "rockerR", "oscillating"),
    ("L4L", "QL", "AL", "rockerL", "upper"),
    ("L4R", "QR", "AR", "rockerR", "upper"),
    ("L5L", "QL", "ML", "L5L", "lower"),
    ("L5R", "QR", "MR", "L5R", "lower"),
    ("m2L", "C2", "ML", "m2", "main"),
    ("m2R", "C2", "MR", "m2", "main"),
)
_M = {m[0]: k for k, m in enumerate(MEMBERS)}

# (point, body a, body b or None for the frame, member whose axis is the joint's load axis)
JOINTS = (
    ("O", "crank", None, "L2"),
    ("B", "crank", "rod", "L2"),
    ("C1", "rod", "m1", "L2"),
    ("DL", "m1", "L3L", "L3L"),
    ("DR", "m1", "L3R", "L3R"),
    ("SL", "L3L", "rockerL", "L3L"),
    ("SR", "L3R", "rockerR", "L3R"),
    ("AL", "rockerL", None, "L4L"),
    ("AR", "rockerR", None, "L4R"),
    ("QL", "rockerL", "L5L", "L5L"),
    ("QR", "rockerR", "L5R", "L5R"),
    ("ML", "L5L", "m2", "L5L"),
    ("MR", "L5R", "m2", "L5R"),
)

SECTIONS = ("crank", "rod", "deputy", "toggle", "upper", "oscillating", "lower", "main")


class PressGeometry(eqx.Module):
    """Dimensions, masses and sections of the press (every number an array leaf, SI units)."""

    O: Float[Array, "2"]
    r1: Float[Array, ""]
    L2: Float[Array, ""]
    c: Float[Array, ""]
    A: Float[Array, "2"]
    L4: Float[Array, ""]
    s_off: Float[Array, "2"]
    L5: Float[Array, ""]
    b: Float[Array, ""]
    m1: Float[Array, ""]
    m2: Float[Array, ""]
    pin_mass: Float[Array, ""]
    E: Float[Array, ""]
    rho: Float[Array, ""]
    depth: Float[Array, " 8"]
    thickness: Float[Array, " 8"]
    bar_A: Float[Array, ""]
    bar_L: Float[Array, ""]
    E_t: Float[Array, ""]
    E_c: Float[Array, ""]
    E_n: Float[Array, ""]
    elements_per_link: int = eqx.field(static=True)

    def bdc_points(self) -> Float[Array, "14 2"]:
        """Positions of the named points at BDC (crank angle 90 deg), m."""
        return press_points(press_q_bdc(self), jnp.pi / 2, self)

    @property
    def L3(self) -> Array:
        y1 = self.O[1] - self.r1 - self.L2
        S = self.A + jnp.array([0.0, -1.0]) * self.L4 + self.s_off
        return jnp.linalg.norm(S - jnp.stack([self.c, y1]))


def _num(cfg: Mapping, key: str, where: str, positive: bool = True, shape: tuple = ()) -> np.ndarray:
    if key not in cfg:
        raise ConfigError(f"{where}.{key}: missing (expected a number in SI units)")
    try:
        v = np.asarray(cfg[key], dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(f"{where}.{key}: expected a number, got {cfg[key]!r}") from None
    if v.shape != shape:
        raise ConfigError(f"{where}.{key}: expected shape {shape}, got {v.shape}")
    if not np.all(np.isfinite(v)) or (positive and np.any(v <= 0)):
        raise ConfigError(f"{where}.{key}: expected a finite {'positive ' if positive else ''}value, got {v.tolist()}")
    return v


def press_from_config(cfg: Mapping) -> PressGeometry:
    """Build :class:`PressGeometry` from the ``press`` and ``joints`` sections of a config mapping.

    Every missing or non-physical field raises :class:`jflex.ConfigError` naming it.
    """
    if "press" not in cfg or not isinstance(cfg["press"], Mapping):
        raise ConfigError("press: missing section (see configs/press.yaml)")
    if "joints" not in cfg or not isinstance(cfg["joints"], Mapping):
        raise ConfigError("joints: missing section (see configs/press.yaml)")
    p, j = cfg["press"], cfg["joints"]
    mat = p.get("material")
    if not isinstance(mat, Mapping):
        raise ConfigError("press.material: expected a mapping with E and rho")
    secs = p.get("sections")
    if not isinstance(secs, Mapping):
        raise ConfigError(f"press.sections: expected a mapping with {', '.join(SECTIONS)}")
    depth, thick = [], []
    for s in SECTIONS:
        if s not in secs or not isinstance(secs[s], Mapping):
            raise ConfigError(f"press.sections.{s}: missing (expected {{depth, thickness}} in m)")
        depth.append(_num(secs[s], "depth", f"press.sections.{s}"))
        thick.append(_num(secs[s], "thickness", f"press.sections.{s}"))
    bdc = float(p.get("bdc_crank_angle_deg", 90.0))
    if abs(bdc - 90.0) > 1e-12:
        raise ConfigError("press.bdc_crank_angle_deg: only 90 (the press paper's convention) is supported")
    n_el = p.get("elements_per_link", 3)
    if not isinstance(n_el, int) or n_el < 1:
        raise ConfigError(f"press.elements_per_link: expected an integer >= 1, got {n_el!r}")
    f = lambda x: jnp.asarray(x, float)
    geo = PressGeometry(
        O=f(_num(p, "crank_pivot", "press", False, (2,))),
        r1=f(_num(p, "crank_radius", "press")),
        L2=f(_num(p, "rod_length", "press")),
        c=f(_num(p, "deputy_half_width", "press")),
        A=f(_num(p, "rocker_pivot", "press", False, (2,))),
        L4=f(_num(p, "upper_link_length", "press")),
        s_off=f(_num(p, "toggle_pin_offset", "press", False, (2,))),
        L5=f(_num(p, "lower_link_length", "press")),
        b=f(_num(p, "main_half_width", "press")),
        m1=f(_num(p, "deputy_mass", "press")),
        m2=f(_num(p, "main_mass", "press")),
        pin_mass=f(_num(p, "pin_mass", "press", positive=False)),
        E=f(_num(mat, "E", "press.material")),
        rho=f(_num(mat, "rho", "press.material")),
        depth=f(np.array(depth)),
        thickness=f(np.array(thick)),
        bar_A=f(_num(j, "bar_area", "joints")),
        bar_L=f(_num(j, "bar_length", "joints")),
        E_t=f(_num(j, "E_tension", "joints")),
        E_c=f(_num(j, "E_compression", "joints")),
        E_n=f(_num(j, "E_transverse", "joints")),
        elements_per_link=n_el,
    )
    if not abs(float(geo.b) - float(geo.A[0])) < float(geo.L5):
        raise ConfigError(
            "press.main_half_width: the lower link cannot reach the slider pin "
            "(|main_half_width - rocker_pivot x| must be < lower_link_length)"
        )
    if float(geo.A[0]) <= float(geo.c):
        raise ConfigError("press.rocker_pivot: the frame pin must lie outside the deputy slider's pins (x > deputy_half_width)")
    for name, m, sec in (("deputy_mass", geo.m1, "deputy"), ("main_mass", geo.m2, "main")):
        k = SECTIONS.index(sec)
        half = geo.c if sec == "deputy" else geo.b
        beam_mass = 2 * float(half * geo.depth[k] * geo.thickness[k] * geo.rho)
        if float(m) < beam_mass:
            raise ConfigError(f"press.{name}: {float(m):.4g} kg is less than its crosshead's steel ({beam_mass:.4g} kg)")
    return geo


def _rot(a):
    c, s = jnp.cos(a), jnp.sin(a)
    return jnp.array([[c, -s], [s, c]])


def _e(a):
    return jnp.stack([jnp.cos(a), jnp.sin(a)])


def _side(q6, y1, geo: PressGeometry, sign: float):
    """Points D, S (toggle side), A, Q, M and the two closure residuals of one side."""
    th3, psi, th5, y2 = q6
    mir = jnp.array([sign, 1.0])
    A = geo.A * mir
    Q0 = (geo.A + jnp.array([0.0, -1.0]) * geo.L4) * mir
    S0 = Q0 + geo.s_off * mir
    R = _rot(sign * psi)
    Q = A + R @ (Q0 - A)
    S = A + R @ (S0 - A)
    D = jnp.stack([sign * geo.c, y1])
    M_from_Q = Q + geo.L5 * _e(th5)
    M = jnp.stack([sign * geo.b, y2])
    return (D, S, A, Q, M), jnp.concatenate([D + geo.L3 * _e(th3) - S, M_from_Q - M])


def press_residual(q: Float[Array, " 10"], phi, geo: PressGeometry) -> Float[Array, " 10"]:
    """Loop-closure equations of the press (10 equations in the 10 coordinates ``q``), m."""
    th2, y1 = q[0], q[1]
    B = geo.O - geo.r1 * _e(phi)
    r0 = B + geo.L2 * _e(th2) - jnp.stack([0.0 * y1, y1])
    _, rR = _side(q[2:6], y1, geo, 1.0)
    _, rL = _side(q[6:10], y1, geo, -1.0)
    return jnp.concatenate([r0, rR, rL])


def press_points(q: Float[Array, " 10"], phi, geo: PressGeometry) -> Float[Array, "14 2"]:
    """Positions of the named points ``POINTS`` for coordinates ``q`` at crank angle ``phi``, m."""
    y1 = q[1]
    B = geo.O - geo.r1 * _e(phi)
    C1 = jnp.stack([0.0 * y1, y1])
    (DR, SR, AR, QR, MR), _ = _side(q[2:6], y1, geo, 1.0)
    (DL, SL, AL, QL, ML), _ = _side(q[6:10], y1, geo, -1.0)
    C2 = jnp.stack([0.0 * q[5], 0.5 * (q[5] + q[9])])
    pts = dict(O=geo.O, B=B, C1=C1, DL=DL, DR=DR, SL=SL, SR=SR, AL=AL, AR=AR, QL=QL, QR=QR, ML=ML, MR=MR, C2=C2)
    return jnp.stack([pts[p] for p in POINTS])


def press_q_bdc(geo: PressGeometry) -> Float[Array, " 10"]:
    """Exact coordinates at BDC (crank angle 90 deg), where the layout is specified."""
    y1 = geo.O[1] - geo.r1 - geo.L2
    Q0 = geo.A + jnp.array([0.0, -1.0]) * geo.L4
    S0 = Q0 + geo.s_off
    d = S0 - jnp.stack([geo.c, y1])
    th3 = jnp.arctan2(d[1], d[0])
    dx = geo.b - Q0[0]
    y2 = Q0[1] - jnp.sqrt(geo.L5**2 - dx**2)
    th5 = jnp.arctan2(y2 - Q0[1], dx)
    th3L = jnp.pi - th3
    z = 0.0 * y1
    return jnp.stack([-jnp.pi / 2 + z, y1, th3, z, th5, y2, th3L, z, jnp.pi - th5, y2])


def press_motion(geo: PressGeometry, phis: Float[Array, " n"]) -> LinkageMotion:
    """Rigid-body motion over crank angles ``phis`` (rad, starting at BDC = pi/2), by continuation."""
    return linkage_motion(press_residual, press_q_bdc(geo), phis, geo)


class PressFE(eqx.Module):
    """A finite-element model of the press in one variant, with the maps from linkage points to nodes."""

    model: FEModel
    variant: str = eqx.field(static=True)
    node_member: tuple[int, ...] = eqx.field(static=True)
    """Member each node belongs to (its rotation follows that member)."""
    node_frac: tuple[float, ...] = eqx.field(static=True)
    """Position of the node along its member, 0 at the start point, 1 at the end."""
    bar_joint: tuple[int, ...] = eqx.field(static=True)
    bar_normal: tuple[bool, ...] = eqx.field(static=True)
    """Per bar: its joint, and whether it is normal to the load axis (bars II, IV)."""
    slider_dof: int = eqx.field(static=True)
    """Global index of the main slider's vertical DOF."""
    axis_elems: tuple[int, ...] = eqx.field(static=True)
    """Per joint: a beam element of its axis member (its axial force sets the bar moduli)."""


def press_fe(geo: PressGeometry, variant: str) -> PressFE:
    """Finite-element model of the press: ``variant`` is ``"perfect"`` or ``"joints"``.

    ``"perfect"``: the links' nodes at a pin share their translations (rotations independent).
    ``"joints"``: each pin is four bar elements between the links' nodes (press paper, Sec. 2.3).
    Frame pins, the crank's input rotation and the sliders' guides (horizontal translation and
    rotation of their centres) are held.
    """
    if variant not in ("perfect", "joints"):
        raise ConfigError(f"variant: expected 'perfect' or 'joints', got {variant!r}")
    n_el = geo.elements_per_link
    E, rho = float(geo.E), float(geo.rho)
    node_member, node_frac = [], []
    end_node = {}  # (body, point) -> node, so a body's members welded at a point share the node
    member_nodes = []
    for k, (name, pa, pb, body, sec) in enumerate(MEMBERS):
        ids = []
        for e in range(n_el + 1):
            key = (body, pa) if e == 0 else (body, pb) if e == n_el else None
            if key is not None and key in end_node:
                ids.append(end_node[key])
                continue
            node_member.append(k)
            node_frac.append(e / n_el)
            ids.append(len(node_member) - 1)
            if key is not None:
                end_node[key] = ids[-1]
        member_nodes.append(ids)
    n_link_nodes = len(node_member)
    # DOF slots: own ones first, then pins couple or fix them.
    slots = [[3 * i, 3 * i + 1, 3 * i + 2] for i in range(n_link_nodes)]
    FIX = -1

    def alias(node, k, target):
        slots[node][k] = target

    bars, bar_joint, bar_normal, masses = [], [], [], []
    axis_elems = []
    for jk, (pt, ba, bb, axis) in enumerate(JOINTS):
        na = end_node[(ba, pt)]
        axis_elems.append(_M[axis] * n_el + (0 if MEMBERS[_M[axis]][1] == pt else n_el - 1))
        masses.append((na, float(geo.pin_mass), 0.0))
        if variant == "perfect":
            if bb is None:
                alias(na, 0, FIX)
                alias(na, 1, FIX)
            else:
                nb = end_node[(bb, pt)]
                alias(nb, 0, slots[na][0])
                alias(nb, 1, slots[na][1])
        else:
            if bb is None:
                node_member.append(_M[axis])
                node_frac.append(0.0 if MEMBERS[_M[axis]][1] == pt else 1.0)
                slots.append([FIX, FIX, FIX])
                nb = len(slots) - 1
            else:
                nb = end_node[(bb, pt)]
            for normal, Ej in ((False, geo.E_t), (True, geo.E_n), (False, geo.E_t), (True, geo.E_n)):
                bars.append((na, nb, float(Ej), float(geo.bar_A), float(geo.bar_L), 0.0))
                bar_joint.append(jk)
                bar_normal.append(normal)
    # The crank's rotation at O is the prescribed input; slider guides hold x and rotation.
    # Fixing a slot fixes the DOF it stands for, in every node that shares it.
    held = {slots[end_node[("crank", "O")]][2]}
    for body, pt in (("m1", "C1"), ("m2", "C2")):
        n = end_node[(body, pt)]
        held |= {slots[n][0], slots[n][2]}
    # Renumber the free slots 0..n_dof-1, keeping shared ones shared.
    remap = {}
    node_dofs = []
    for s in slots:
        row = []
        for d in s:
            if d == FIX or d in held:
                row.append(-1)
            else:
                remap.setdefault(d, len(remap))
                row.append(remap[d])
        node_dofs.append(tuple(row))
    beams = []
    for k, (name, pa, pb, body, sec) in enumerate(MEMBERS):
        si = SECTIONS.index(sec)
        h, t = float(geo.depth[si]), float(geo.thickness[si])
        for e in range(n_el):
            beams.append((member_nodes[k][e], member_nodes[k][e + 1], E, h * t, t * h**3 / 12, rho))
    cross = {"m1": (geo.m1, "deputy", geo.c), "m2": (geo.m2, "main", geo.b)}
    for body, pt in (("m1", "C1"), ("m2", "C2")):
        m, sec, half = cross[body]
        si = SECTIONS.index(sec)
        steel = 2 * float(half * geo.depth[si] * geo.thickness[si] * geo.rho)
        masses.append((end_node[(body, pt)], float(m) - steel, 0.0))
    model = fe_model(node_dofs, beams, bars, masses)
    return PressFE(
        model=model,
        variant=variant,
        node_member=tuple(node_member),
        node_frac=tuple(node_frac),
        bar_joint=tuple(bar_joint),
        bar_normal=tuple(bar_normal),
        slider_dof=node_dofs[end_node[("m2", "C2")]][1],
        axis_elems=tuple(axis_elems),
    )


class PressPoses(eqx.Module):
    """Everything about the press at n poses that does not depend on speed."""

    phi: Float[Array, " n"]
    """Crank angles, rad (pose 0 is BDC)."""
    X: Float[Array, "n nn 2"]
    """Node positions, m."""
    M: Float[Array, "n N N"]
    K: Float[Array, "n N N"]
    G: Float[Array, "n N"]
    """Inertial load per unit crank speed squared, ``-M U_r''`` (N s^2 per rad^2): ``F = omega^2 G``."""
    slider_rigid: Float[Array, " n"]
    """Rigid-body height of the main slider, m."""
    bar_E: Float[Array, "n nr"]
    """Modulus chosen for every joint bar at each pose, Pa."""


def _angle_derivs(d, dd, ddd):
    n2 = d @ d
    cross = lambda a, b: a[0] * b[1] - a[1] * b[0]
    th = jnp.arctan2(d[1], d[0])
    th1 = cross(d, dd) / n2
    th2 = cross(d, ddd) / n2 - 2.0 * (d @ dd) * cross(d, dd) / n2**2
    return th, th1, th2


@eqx.filter_jit
def _poses(pfe: PressFE, geo: PressGeometry, motion: LinkageMotion):
    P, dP, ddP = point_motion(press_points, motion, geo)  # (n, 14, 2)
    starts = np.array([_P[m[1]] for m in MEMBERS])
    ends = np.array([_P[m[2]] for m in MEMBERS])
    d = P[:, ends] - P[:, starts]
    dd = dP[:, ends] - dP[:, starts]
    ddd = ddP[:, ends] - ddP[:, starts]
    th, _, th2 = jax.vmap(jax.vmap(_angle_derivs))(d, dd, ddd)  # (n, members)
    nm = np.array(pfe.node_member)
    fr = jnp.array(pfe.node_frac)[None, :, None]
    X = (1 - fr) * P[:, starts[nm]] + fr * P[:, ends[nm]]
    acc = (1 - fr) * ddP[:, starts[nm]] + fr * ddP[:, ends[nm]]
    acc = jnp.concatenate([acc, th2[:, nm][..., None]], axis=-1)  # (n, nodes, 3)
    jointaxis = th[:, np.array([_M[j[3]] for j in JOINTS])] if pfe.bar_joint else None
    model = pfe.model

    def pose(Xi, acci, axes):
        Ur = model.gather(acci)
        if not pfe.bar_joint:
            M, K = model.matrices(Xi)
            return M, K, -M @ Ur, jnp.zeros((0,))
        bj = np.array(pfe.bar_joint)
        nrm = np.array(pfe.bar_normal)
        ang = axes[bj] + jnp.where(nrm, jnp.pi / 2, 0.0)
        E_mean = jnp.where(nrm, geo.E_n, 0.5 * (geo.E_t + geo.E_c))
        M, K0 = model.matrices(Xi, ang, E_mean)
        F = -M @ Ur
        # Tension or compression of each joint's link, from the quasi-static response.
        Us = model.scatter(jnp.linalg.solve(K0, F))
        bn = np.array(model.beam_nodes)[np.array(pfe.axis_elems)]
        du = Us[bn[:, 1], :2] - Us[bn[:, 0], :2]
        dx = Xi[bn[:, 1]] - Xi[bn[:, 0]]
        N = jnp.sum(du * dx, axis=-1)
        E = jnp.where(nrm, geo.E_n, jnp.where(N[bj] >= 0, geo.E_t, geo.E_c))
        _, K = model.matrices(Xi, ang, E)
        return M, K, F, E

    M, K, G, E = jax.vmap(pose)(X, acc, jointaxis if jointaxis is not None else jnp.zeros((X.shape[0], 0)))
    return X, M, K, G, P[:, _P["C2"], 1], E


def press_poses(geo: PressGeometry, pfe: PressFE, n_poses: int) -> PressPoses:
    """Mass, stiffness and unit-speed inertial load of the press at ``n_poses`` crank angles from BDC.

    **Arguments:**

    - `geo`: the press.
    - `pfe`: its finite-element model (:func:`press_fe`).
    - `n_poses`: equally spaced poses over one revolution, starting at BDC.

    **Returns:** :class:`PressPoses`.
    """
    phis = jnp.pi / 2 + 2 * jnp.pi * jnp.arange(n_poses) / n_poses
    motion = press_motion(geo, phis)
    X, M, K, G, ys, E = _poses(pfe, geo, motion)
    return PressPoses(phi=phis, X=X, M=M, K=K, G=G, slider_rigid=ys, bar_E=E)


def spm_to_rad_s(spm) -> float:
    """Strokes per minute to crank angular speed, rad/s."""
    return 2 * math.pi * float(spm) / 60.0
