"""The rigid core of every model: a kinematic tree with inertial parameters.

Topology (names, parents, joint types) is static; every physical number is an array leaf, so
any of them can be differentiated or fitted and a new value never retraces.
"""

from __future__ import annotations

from typing import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._errors import ParameterError, ShapeError

REVOLUTE = "revolute"
PRISMATIC = "prismatic"
JOINT_TYPES = (REVOLUTE, PRISMATIC)


class Robot(eqx.Module):
    """A fixed-base kinematic tree of ``n`` moving joints, each carrying one rigid link.

    Body frame ``i`` is the frame of joint ``i`` (child side): it sits at
    ``placement_R[i], placement_p[i]`` in the body frame of ``parents[i]`` (``-1``: the base) when
    ``q[i] = 0``, and moves by a rotation about / translation along ``axis[i]`` (unit, in body
    axes). Fixed joints are merged at build time; what they carried survives as named frames.

    **Fields** (leaves are arrays; ``n`` joints, ``nf`` extra frames):

    - ``joint_names``, ``link_names``, ``parents``, ``joint_types``: static tuples.
    - ``placement_R`` (n, 3, 3), ``placement_p`` (n, 3) [m].
    - ``axis`` (n, 3): joint axes in body axes.
    - ``inertia`` (n, 10): per link ``[m, m c_x, m c_y, m c_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz]``
      [kg, kg m, kg m^2], inertia about the body-frame origin (Pinocchio's order).
    - ``gravity`` (3,) [m/s^2] in base axes.
    - ``lower``, ``upper`` (n,) [rad or m]; ``velocity_limit`` (n,); ``effort_limit`` (n,).
    - ``frame_names``, ``frame_parents`` (static): extra named frames (tool, merged links) on body
      ``frame_parents[k]`` (``-1``: base) at ``frame_R[k], frame_p[k]``.
    - ``mimic`` (static), ``mimic_multiplier``, ``mimic_offset`` (n,): coupled joints (a URDF's
      ``<mimic>``), empty / ``None`` for a robot without them. ``mimic[i] = k >= 0``: joint ``i``
      has no coordinate of its own and moves at ``mimic_multiplier[i] * q_k + mimic_offset[i]``
      with its leader ``k``, an independent joint (``-1``). As in Pinocchio, the coordinates ``q``
      are the independent joints in tree order (:attr:`coordinate_names`, ``nq`` of them) while
      ``joint_names``, the leaves above, forward kinematics and ``f_ext`` run over every joint of the
      tree (:attr:`n_joints`).
    """

    placement_R: jnp.ndarray
    placement_p: jnp.ndarray
    axis: jnp.ndarray
    inertia: jnp.ndarray
    gravity: jnp.ndarray
    lower: jnp.ndarray
    upper: jnp.ndarray
    velocity_limit: jnp.ndarray
    effort_limit: jnp.ndarray
    frame_R: jnp.ndarray
    frame_p: jnp.ndarray
    joint_names: tuple[str, ...] = eqx.field(static=True)
    link_names: tuple[str, ...] = eqx.field(static=True)
    parents: tuple[int, ...] = eqx.field(static=True)
    joint_types: tuple[str, ...] = eqx.field(static=True)
    frame_names: tuple[str, ...] = eqx.field(static=True, default=())
    frame_parents: tuple[int, ...] = eqx.field(static=True, default=())
    base_name: str = eqx.field(static=True, default="base")
    mimic: tuple[int, ...] = eqx.field(static=True, default=())
    mimic_multiplier: jnp.ndarray | None = None
    mimic_offset: jnp.ndarray | None = None

    def __check_init__(self):
        n = len(self.parents)
        if not (len(self.joint_names) == len(self.link_names) == len(self.joint_types) == n):
            raise ShapeError("Robot: joint_names, link_names, joint_types and parents must have one entry per joint")
        for i, p in enumerate(self.parents):
            if not -1 <= p < i:
                raise ShapeError(
                    f"Robot: joint '{self.joint_names[i]}' has parent index {p}; parents must come before "
                    "their children (topological order) and -1 stands for the base"
                )
        for i, t in enumerate(self.joint_types):
            if t not in JOINT_TYPES:
                raise ShapeError(f"Robot: joint '{self.joint_names[i]}' has type '{t}', expected one of {JOINT_TYPES}")
        if len(set(self.joint_names)) != n:
            raise ShapeError("Robot: joint names must be unique")
        if self.mimic:
            if len(self.mimic) != n or self.mimic_multiplier is None or self.mimic_offset is None:
                raise ShapeError("Robot: mimic needs one entry per joint, with mimic_multiplier and mimic_offset")
            for i, k in enumerate(self.mimic):
                if k >= 0 and (k >= n or k == i or self.mimic[k] >= 0):
                    raise ShapeError(
                        f"Robot: joint '{self.joint_names[i]}' mimics index {k}; a leader must be another joint "
                        "of the robot that mimics none"
                    )
            if all(k < 0 for k in self.mimic):
                raise ShapeError("Robot: mimic lists no coupled joint; leave it empty")
        elif self.mimic_multiplier is not None or self.mimic_offset is not None:
            raise ShapeError("Robot: mimic_multiplier and mimic_offset need mimic")

    @property
    def n_joints(self) -> int:
        """Number of joints (bodies) of the tree, coupled ones included."""
        return len(self.parents)

    @property
    def nq(self) -> int:
        """Number of joint coordinates: the joints, less those that mimic another."""
        return len(self.parents) - sum(k >= 0 for k in self.mimic)

    @property
    def nv(self) -> int:
        return self.nq

    @property
    def coordinate_names(self) -> tuple[str, ...]:
        """The joints that carry a coordinate of ``q``, in order (``joint_names`` without mimic joints)."""
        if not self.mimic:
            return self.joint_names
        return tuple(nm for nm, k in zip(self.joint_names, self.mimic) if k < 0)

    def frame_index(self, frame: int | str) -> tuple[int, int]:
        """Resolve a frame (link index, link name, joint name or extra frame name) statically.

        Returns ``(body, k)``: the body it is attached to and ``k`` the extra-frame index, or -1
        when the frame is the body frame itself.
        """
        if isinstance(frame, (int, np.integer)):
            if not 0 <= int(frame) < self.n_joints:
                raise ShapeError(f"frame index {frame} out of range for a robot with {self.n_joints} links")
            return int(frame), -1
        if frame in self.link_names:
            return self.link_names.index(frame), -1
        if frame in self.joint_names:
            return self.joint_names.index(frame), -1
        if frame in self.frame_names:
            k = self.frame_names.index(frame)
            return self.frame_parents[k], k
        known = list(self.link_names) + list(self.frame_names)
        raise ShapeError(f"unknown frame '{frame}'; known frames: {known}")

    def replace(self, **kw) -> "Robot":
        """A copy with the named leaves replaced (e.g. ``robot.replace(inertia=new)``)."""
        names = list(kw)
        return eqx.tree_at(lambda r: [getattr(r, k) for k in names], self, [jnp.asarray(kw[k]) for k in names])


def _on_device(x):
    # a host array placed on the device as it is: jnp.asarray would compile a copy program per shape
    # (jax 0.10), seven for one robot, a second of a URDF's load
    return jax.device_put(np.asarray(x, dtype=float))


# the heaviest moving machines weigh about 1e7 kg; a link beyond this is a unit or typing slip
MAX_MASS_KG = 1e9


def make_robot(
    *,
    joint_names: Sequence[str],
    link_names: Sequence[str],
    parents: Sequence[int],
    joint_types: Sequence[str],
    placement_R,
    placement_p,
    axis,
    inertia=None,
    gravity=(0.0, 0.0, -9.81),
    lower=None,
    upper=None,
    velocity_limit=None,
    effort_limit=None,
    frame_names: Sequence[str] = (),
    frame_parents: Sequence[int] = (),
    frame_R=None,
    frame_p=None,
    base_name: str = "base",
    check_physical: bool = True,
    mimic: Sequence[tuple[str, str, float, float]] = (),
) -> Robot:
    """Build a :class:`Robot`, validating shapes and physical consistency (named errors).

    ``check_physical=False`` skips the physical-consistency check of the inertias (a builder that
    checked them itself, e.g. :func:`load_urdf`, which loads vendor inertias with a warning).
    ``mimic``: ``(joint, leader, multiplier, offset)`` per coupled joint, by name: ``joint`` moves at
    ``multiplier * q_leader + offset`` and has no coordinate of its own (see :class:`Robot`)."""
    n = len(parents)
    if n == 0:
        raise ParameterError("Robot: no joints (parents is empty); expected at least one moving joint")

    def arr(x, shape, field):
        a = np.asarray(x, dtype=float)
        if a.shape != shape:
            raise ShapeError(f"Robot.{field}: expected shape {shape}, got {a.shape}")
        if field in ("lower", "upper", "velocity_limit", "effort_limit"):
            if np.isnan(a).any():  # limits may be infinite (no limit), never NaN
                raise ParameterError(f"Robot.{field}: contains NaN")
        elif not np.all(np.isfinite(a)):
            raise ParameterError(f"Robot.{field}: contains NaN or inf")
        return a

    ax = arr(axis, (n, 3), "axis")
    norms = np.linalg.norm(ax, axis=1)
    for i in range(n):
        if not norms[i] > 0:
            raise ParameterError(f"joint '{joint_names[i]}': axis must be non-zero, got {ax[i].tolist()}")
    ax = ax / norms[:, None]
    inertia = np.zeros((n, 10)) if inertia is None else arr(inertia, (n, 10), "inertia")
    for i in range(n if check_physical else 0):
        check_inertia(inertia[i], f"link '{link_names[i]}'")
    for i in range(n):
        # finite but absurd: the inverse dynamics square such numbers (kinetic energy, the regressor's
        # Gram matrix) and overflow, and what follows reads inf or a constant torque
        if abs(inertia[i, 0]) > MAX_MASS_KG or np.abs(inertia[i, 4:]).max() > MAX_MASS_KG * 1e3:
            raise ParameterError(f"link '{link_names[i]}': mass {inertia[i, 0]:.3g} kg, rotational inertia up to "
                                 f"{np.abs(inertia[i, 4:]).max():.3g} kg m^2: expected a machine's (mass at most "
                                 f"{MAX_MASS_KG:.0e} kg, inertia at most {MAX_MASS_KG * 1e3:.0e} kg m^2; a unit slip?)")
    nf = len(frame_names)
    fR = np.tile(np.eye(3), (nf, 1, 1)) if frame_R is None else arr(frame_R, (nf, 3, 3), "frame_R")
    fp = np.zeros((nf, 3)) if frame_p is None else arr(frame_p, (nf, 3), "frame_p")
    full = lambda x, v, field: np.full(n, v) if x is None else arr(x, (n,), field)
    lo, hi = full(lower, -np.inf, "lower"), full(upper, np.inf, "upper")
    for i in range(n):
        if lo[i] > hi[i]:
            raise ParameterError(f"joint '{joint_names[i]}': lower limit {lo[i]} exceeds upper limit {hi[i]}")
    lead, mult, off = _coupling(list(joint_names), mimic)
    return Robot(
        placement_R=_on_device(arr(placement_R, (n, 3, 3), "placement_R")),
        placement_p=_on_device(arr(placement_p, (n, 3), "placement_p")),
        axis=_on_device(ax),
        inertia=_on_device(inertia),
        gravity=_on_device(arr(gravity, (3,), "gravity")),
        lower=_on_device(lo),
        upper=_on_device(hi),
        velocity_limit=_on_device(full(velocity_limit, np.inf, "velocity_limit")),
        effort_limit=_on_device(full(effort_limit, np.inf, "effort_limit")),
        frame_R=_on_device(fR.reshape(nf, 3, 3)),
        frame_p=_on_device(fp.reshape(nf, 3)),
        joint_names=tuple(joint_names),
        link_names=tuple(link_names),
        parents=tuple(int(p) for p in parents),
        joint_types=tuple(joint_types),
        frame_names=tuple(frame_names),
        frame_parents=tuple(int(p) for p in frame_parents),
        base_name=base_name,
        mimic=lead,
        mimic_multiplier=mult,
        mimic_offset=off,
    )


def _coupling(names, mimic):
    """(mimic, multiplier, offset) fields of :class:`Robot` from ``(joint, leader, multiplier,
    offset)`` tuples; a leader that mimics a third joint is followed to the independent one."""
    if not mimic:
        return (), None, None
    n = len(names)
    spec = {}
    for entry in mimic:
        if len(entry) != 4:
            raise ShapeError(f"Robot.mimic: expected (joint, leader, multiplier, offset), got {entry!r}")
        j, lead, a, b = entry
        for nm in (j, lead):
            if nm not in names:
                raise ShapeError(f"Robot.mimic: unknown joint '{nm}'; joints: {names}")
        if j in spec:
            raise ShapeError(f"Robot.mimic: joint '{j}' mimics twice")
        a, b = float(a), float(b)
        if not (np.isfinite(a) and np.isfinite(b)):
            raise ParameterError(f"Robot.mimic: joint '{j}': multiplier and offset must be finite, got {a}, {b}")
        spec[j] = (lead, a, b)
    lead_idx, mult, off = [-1] * n, np.ones(n), np.zeros(n)
    for j in spec:
        a, b, k, seen = 1.0, 0.0, j, [j]
        while k in spec:  # q_k = a_k q_leader + b_k, composed down the chain
            k, ak, bk = spec[k]
            a, b = a * ak, a * bk + b
            if k in seen:
                raise ShapeError(f"Robot.mimic: joints {seen} mimic each other in a cycle")
            seen.append(k)
        i = names.index(j)
        lead_idx[i], mult[i], off[i] = names.index(k), a, b
    return tuple(lead_idx), jnp.asarray(mult), jnp.asarray(off)


def inertia_defect(pi, rtol: float = 1e-9) -> str | None:
    """Why the 10 parameters ``pi`` are not physically consistent, or ``None`` when they are:
    m >= 0, and the inertia about the centre of mass positive semi-definite with the triangle
    inequalities. Round-off up to ``rtol`` of the body's own scale (its largest moment about the
    frame origin or the centre of mass) is tolerated, so a point mass (zero moments about its
    centre of mass) and moments of -1e-22 beside 0.1 pass."""
    pi = np.asarray(pi, dtype=float)
    m = pi[0]
    if not np.isfinite(pi).all():
        return "inertial parameters contain NaN or inf"
    if m < 0:
        return f"mass must be >= 0, got {m}"
    I_o = np.array([[pi[4], pi[5], pi[7]], [pi[5], pi[6], pi[8]], [pi[7], pi[8], pi[9]]])
    if m == 0:
        if np.abs(pi[1:4]).max() > 0:
            return f"zero mass but non-zero first moment m*c = {pi[1:4].tolist()}"
        I_c = I_o
    else:
        c = pi[1:4] / m
        I_c = I_o - m * (c @ c * np.eye(3) - np.outer(c, c))
    ev = np.linalg.eigvalsh(I_c)
    tol = rtol * max(np.abs(ev).max(), np.abs(I_o).max())
    if ev.min() < -tol:
        return (
            "rotational inertia about the centre of mass is not positive semi-definite "
            f"(principal moments {[float(e) for e in ev]})"
        )
    a, b, c3 = np.sort(ev)
    if a + b < c3 - tol:
        return f"principal moments {[float(a), float(b), float(c3)]} violate the triangle inequality I1 + I2 >= I3"
    return None


def check_inertia(pi, where: str, rtol: float = 1e-9) -> None:
    """Raise :class:`ParameterError` naming ``where`` unless ``pi`` is physically consistent
    (see :func:`inertia_defect`)."""
    defect = inertia_defect(pi, rtol)
    if defect is not None:
        raise ParameterError(f"{where}: {defect}")


def check_q(robot: Robot, q, name: str = "q"):
    """Shape check before tracing: ``q`` must have one entry per coordinate (batches go through vmap)."""
    shape = jnp.shape(q)
    if shape != (robot.nq,):
        raise ShapeError(
            f"{name} must have shape ({robot.nq},) for this robot (joints {list(robot.coordinate_names)}), got {shape}; "
            "batch with jax.vmap or jflex.sweep"
        )


def move_params(pi, T) -> np.ndarray:
    """10 inertial parameters given in frame A -> the same body in frame B, A sitting at the 4x4
    transform ``T`` in B (NumPy; for builders)."""
    pi = np.asarray(pi, dtype=float)
    m = pi[0]
    R, p = T[:3, :3], T[:3, 3]
    I_o = np.array([[pi[4], pi[5], pi[7]], [pi[5], pi[6], pi[8]], [pi[7], pi[8], pi[9]]])
    if m == 0:
        # A massless body may still carry rotational inertia (bolt's feet): it only rotates.
        I2 = R @ I_o @ R.T
        return np.array([0.0, 0.0, 0.0, 0.0, I2[0, 0], I2[0, 1], I2[1, 1], I2[0, 2], I2[1, 2], I2[2, 2]])
    c = pi[1:4] / m
    I_c = I_o - m * (c @ c * np.eye(3) - np.outer(c, c))
    c2 = R @ c + p
    I2 = R @ I_c @ R.T + m * (c2 @ c2 * np.eye(3) - np.outer(c2, c2))
    return np.array([m, *(m * c2), I2[0, 0], I2[0, 1], I2[1, 1], I2[0, 2], I2[1, 2], I2[2, 2]])
