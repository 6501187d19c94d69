"""Flexible joints: a torsion spring and damper between each link and its motor (Eq. 2.8 of
the thesis "Posture Dependent Dynamics in Robotic Machining";
"serial system dynamics with flexible joints" in the course notes "Manipulator modeling accounting for flexibilities").

The effect adds one motor coordinate ``theta_<joint>`` per flexible joint: the rotor angle
*after* the gear (rotor angle / r), so the spring torque is ``K (q - theta)`` and the reflected
rotor inertia is ``r^2 I_m``. With ``coupling=True`` (the full model of the course notes) each rotor
spins on the link that carries it, with absolute spin rate ``r theta_dot + z . omega_parent``:

$$ T_m = \\tfrac12 \\sum_i I_{m,i} (r_i \\dot\\theta_i + z_i\\cdot\\omega_{p(i)})^2, $$

which yields the inertial coupling ``S(q)`` between link and motor accelerations and a small
posture-dependent link inertia. ``coupling=False`` is the reduced (Spong) model,
``T_m = 1/2 sum r_i^2 I_m,i theta_dot_i^2``. Rotor mass and transverse inertia are taken as part
of the carrying link's inertial parameters (they move with it), as the base parameters of
the thesis' Table A.2 do.

The actuators move from the link coordinates to the motor coordinates (``actuation``), so
``jflex.model_forward_dynamics`` / ``model_inverse_dynamics`` of a model with this effect are
the forward / inverse dynamics of the augmented system ``[q, theta]``.
"""

from __future__ import annotations

from typing import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import ParameterError, ShapeError
from .._robot import REVOLUTE
from .._tree import joint_transform
from ._base import AbstractEffect, Slots


def _concrete(x):
    """NumPy value of ``x``, or None when it is traced (checks then happen in jit via error_if)."""
    try:
        return np.asarray(x, dtype=float)
    except Exception:  # a tracer: value checks are skipped, shapes were checked at build time
        return None


def _angular_velocities(robot, q, qd):
    """Body angular velocities (body axes) only: the rotor coupling needs nothing else, and
    skipping positions and linear velocities keeps the nested autodiff of the Lagrange terms
    (and its compile time) small."""
    w = []
    for i in range(robot.nq):
        R, _ = joint_transform(robot, i, q[i])
        p = robot.parents[i]
        wi = jnp.zeros(3, dtype=qd.dtype) if p < 0 else R.T @ w[p]
        if robot.joint_types[i] == REVOLUTE:
            wi = wi + robot.axis[i] * qd[i]
        w.append(wi)
    return w


def _smooth_sign(v, v_s):
    # tanh keeps the force differentiable; v_s sets the width of the transition
    return jnp.tanh(v / v_s)


def _smooth_abs_integral(u, eps):
    # F(u) = int sqrt(u^2 + eps^2) du
    r = jnp.sqrt(u * u + eps * eps)
    return 0.5 * (u * r + eps * eps * jnp.arcsinh(u / eps))


def smooth_saturation(d, b, eps):
    """``(sqrt((d + b)^2 + eps^2) - sqrt((d - b)^2 + eps^2)) / 2``: the clamp of ``d`` to
    ``[-b, b]`` with its corners rounded over ``eps`` (its slope lies in [0, 1); exactly 0 for
    ``b = 0``). The smooth dead zone of a transmission with play is ``d - smooth_saturation(d, b, eps)``."""
    return 0.5 * (jnp.sqrt((d + b) ** 2 + eps * eps) - jnp.sqrt((d - b) ** 2 + eps * eps))


def smooth_dead_zone(d, b, eps):
    """Smooth dead zone of half-width ``b``: ``~ sign(d) max(|d| - b, 0)``, corners rounded over
    ``eps`` (slope in (0, 1]: the spring never stiffens beyond ``k`` nor turns negative);
    ``d`` exactly for ``b = 0``. Beyond the corner (``|d| - b >> eps``) it is
    ``d - b sign(d)`` to ``eps^2 / (4 (|d| - b))``."""
    return d - smooth_saturation(d, b, eps)


def _saturation_energy(d, b, eps):
    # int_0^d smooth_saturation: exactly 0 for b = 0 (the same numbers subtracted)
    return 0.5 * ((_smooth_abs_integral(d + b, eps) - _smooth_abs_integral(d - b, eps))
                  - (_smooth_abs_integral(b, eps) - _smooth_abs_integral(-b, eps)))


class FlexibleJoints(AbstractEffect):
    """Torsion spring + damper between link and motor at the selected joints.

    **Fields** (``m`` flexible joints; every number an array leaf):

    - ``joints``: static tuple of the robot joint indices that are flexible (order of theta).
    - ``stiffness``: (m,) diagonal or (m, m) symmetric positive-definite K [N m/rad].
    - ``damping``: (m,) or (m, m) joint damping B between link and motor [N m s/rad].
    - ``rotor_inertia``: (m,) rotor spin inertia I_m^zz on the motor side of the gear [kg m^2].
    - ``gear_ratio``: (m,) r (motor angle / joint angle) [-].
    - ``link_viscous``, ``link_coulomb``: (m,) link-side friction F_vq [N m s/rad], F_sq [N m].
    - ``motor_viscous``, ``motor_coulomb``: (m,) motor-side friction (after the gear) F_vm, F_sm.
    - ``coulomb_velocity``: () smoothing velocity of the Coulomb terms [rad/s] (tanh(v / v_s)).
    - ``coupling``: static; True for the full model with S(q), False for the reduced Spong model.
    - ``play``: (m,) or None (default: no play, the plain spring). Half-width ``b`` [rad] of the
      play (backlash) inside each transmission: the spring torque is ``k dz(theta - q, b) + c
      (theta_dot - q_dot)`` with ``dz`` a dead zone of half-width ``b`` (inside it the link is
      free of the spring; the damper acts throughout). Diagonal stiffness only.
    - ``play_smoothing``: () width ``eps`` [rad] over which the dead zone's corners are rounded
      (:func:`smooth_dead_zone`; default 1e-5 rad): the spring's stiffness goes from ~0 to ``k``
      within a few ``eps`` of ``|theta - q| = b``, so adaptive ODE solvers and forward-mode
      Jacobians (in ``b`` too) meet a smooth force; a sharp corner would make the solver hunt for
      each contact and the Jacobian jump. The stiffness left in the middle of the gap is
      ``~ k eps^2 / (2 b^2)``; the static deflection under a torque ``tau`` is ``b + tau / k`` to
      ``~ eps^2 k / (4 tau)``. Play 0 is the plain spring exactly (bit for bit).

    The play enters as the spring's potential energy ``k (d^2 / 2 - int_0^d sat)`` (``sat`` the
    smooth clamp to [-b, b]), so the spring stays conservative and the Lagrangian machinery
    (energy, linearisation) holds.

    Note: a smooth Coulomb term linearises at rest to a viscous coefficient F_s / v_s; set the
    Coulomb coefficients to 0 for a modal analysis in the sense of the thesis (Coulomb neglected).
    """

    stiffness: jnp.ndarray
    damping: jnp.ndarray
    rotor_inertia: jnp.ndarray
    gear_ratio: jnp.ndarray
    link_viscous: jnp.ndarray
    link_coulomb: jnp.ndarray
    motor_viscous: jnp.ndarray
    motor_coulomb: jnp.ndarray
    coulomb_velocity: jnp.ndarray
    play: jnp.ndarray | None
    play_smoothing: jnp.ndarray | None
    joints: tuple[int, ...] = eqx.field(static=True)
    coupling: bool = eqx.field(static=True, default=True)

    def __init__(
        self,
        stiffness,
        damping=None,
        rotor_inertia=None,
        gear_ratio=None,
        *,
        joints: Sequence[int] | None = None,
        link_viscous=None,
        link_coulomb=None,
        motor_viscous=None,
        motor_coulomb=None,
        coulomb_velocity=1e-3,
        coupling: bool = True,
        play=None,
        play_smoothing=1e-5,
    ):
        K = jnp.asarray(stiffness, dtype=float)
        if K.ndim not in (1, 2):
            raise ShapeError(f"FlexibleJoints.stiffness: expected (m,) or (m, m) [N m/rad], got shape {K.shape}")
        m = K.shape[0]
        if K.ndim == 2 and K.shape != (m, m):
            raise ShapeError(f"FlexibleJoints.stiffness: a matrix must be square, got shape {K.shape}")
        self.joints = tuple(range(m)) if joints is None else tuple(int(j) for j in joints)
        if len(self.joints) != m:
            raise ShapeError(f"FlexibleJoints.joints: {len(self.joints)} joints but stiffness has {m} rows")
        if len(set(self.joints)) != m or min(self.joints, default=0) < 0:
            raise ShapeError(f"FlexibleJoints.joints: expected distinct non-negative joint indices, got {self.joints}")

        def vec(x, name, default):
            a = jnp.full((m,), default, dtype=float) if x is None else jnp.asarray(x, dtype=float)
            if a.shape == ():
                a = jnp.full((m,), a)
            if a.shape != (m,):
                raise ShapeError(f"FlexibleJoints.{name}: expected shape ({m},), got {a.shape}")
            return a

        D = jnp.zeros(m) if damping is None else jnp.asarray(damping, dtype=float)
        if D.shape not in ((m,), (m, m)):
            raise ShapeError(f"FlexibleJoints.damping: expected ({m},) or ({m}, {m}) [N m s/rad], got {D.shape}")
        self.stiffness = K
        self.damping = D
        self.rotor_inertia = vec(rotor_inertia, "rotor_inertia", 0.0)
        self.gear_ratio = vec(gear_ratio, "gear_ratio", 1.0)
        self.link_viscous = vec(link_viscous, "link_viscous", 0.0)
        self.link_coulomb = vec(link_coulomb, "link_coulomb", 0.0)
        self.motor_viscous = vec(motor_viscous, "motor_viscous", 0.0)
        self.motor_coulomb = vec(motor_coulomb, "motor_coulomb", 0.0)
        self.coulomb_velocity = jnp.asarray(coulomb_velocity, dtype=float)
        self.coupling = bool(coupling)
        if play is None:
            self.play = self.play_smoothing = None
        else:
            if K.ndim != 1:
                raise ShapeError("FlexibleJoints.play: play needs a diagonal stiffness (m,); got a stiffness matrix")
            self.play = vec(play, "play", 0.0)
            self.play_smoothing = jnp.asarray(play_smoothing, dtype=float)
            if self.play_smoothing.shape != ():
                raise ShapeError(f"FlexibleJoints.play_smoothing: expected a scalar [rad], got shape {self.play_smoothing.shape}")

    def __check_init__(self):
        K = _concrete(self.stiffness)
        if K is not None:
            if K.ndim == 1 and not np.all(K > 0):
                bad = [self.joints[i] for i in np.flatnonzero(~(K > 0))]
                raise ParameterError(
                    f"FlexibleJoints.stiffness: every joint stiffness must be > 0 [N m/rad]; joints {bad} have "
                    f"{K[~(K > 0)].tolist()} (a rigid joint is simply left out of `joints`)"
                )
            if K.ndim == 2:
                if not np.allclose(K, K.T, rtol=1e-10, atol=0):
                    raise ParameterError("FlexibleJoints.stiffness: the stiffness matrix must be symmetric")
                if not np.all(np.isfinite(K)) or np.linalg.eigvalsh(K).min() <= 0:
                    raise ParameterError("FlexibleJoints.stiffness: the stiffness matrix must be positive definite")
        for name in ("damping", "rotor_inertia", "link_viscous", "link_coulomb", "motor_viscous", "motor_coulomb"):
            a = _concrete(getattr(self, name))
            if a is not None and not (np.all(np.isfinite(a)) and np.all(np.diagonal(a) >= 0 if a.ndim == 2 else a >= 0)):
                raise ParameterError(f"FlexibleJoints.{name}: must be finite and >= 0, got {a.tolist()}")
        r = _concrete(self.gear_ratio)
        if r is not None and not np.all(r > 0):
            raise ParameterError(f"FlexibleJoints.gear_ratio: must be > 0, got {r.tolist()}")
        if self.play is not None:
            b = _concrete(self.play)
            if b is not None and not (np.all(np.isfinite(b)) and np.all(b >= 0)):
                bad = [self.joints[i] for i in np.flatnonzero(~(np.isfinite(b) & (b >= 0)))]
                raise ParameterError(
                    f"FlexibleJoints.play: every play (backlash half-width) must be finite and >= 0 [rad]; joints {bad} "
                    f"have {b[~(np.isfinite(b) & (b >= 0))].tolist()}"
                )
            eps = _concrete(self.play_smoothing)
            if eps is not None and not (np.isfinite(eps) and eps > 0):
                raise ParameterError(f"FlexibleJoints.play_smoothing: must be finite and > 0 [rad], got {eps}")
        vs = _concrete(self.coulomb_velocity)
        if vs is not None and not vs > 0:
            raise ParameterError(f"FlexibleJoints.coulomb_velocity: must be > 0 [rad/s], got {vs}")

    # -- helpers -------------------------------------------------------------------------------
    def _check_robot(self, robot):
        for j in self.joints:
            if j >= robot.nq:
                raise ShapeError(f"FlexibleJoints.joints: joint index {j} out of range for a robot with {robot.nq} joints")
            if self.coupling and robot.joint_types[j] != REVOLUTE:
                raise ParameterError(
                    f"FlexibleJoints: joint '{robot.joint_names[j]}' is prismatic; the rotor coupling needs revolute "
                    "joints (use coupling=False)"
                )

    def _split(self, slots: Slots, x):
        idx = jnp.array(self.joints, dtype=int)
        return x[idx], x[slots.coords]

    def _matrix(self, a):
        return jnp.diag(a) if a.ndim == 1 else a

    # -- interface -------------------------------------------------------------------------------
    def coord_names(self, robot) -> tuple[str, ...]:
        self._check_robot(robot)
        return tuple(f"theta_{robot.joint_names[j]}" for j in self.joints)

    def coords_at_posture(self, robot, slots: Slots, q):
        """Motor angles of an unloaded spring at link posture ``q``: theta = q."""
        return jnp.asarray(q)[jnp.array(self.joints, dtype=int)]

    def kinetic_energy(self, robot, slots: Slots, x, xd):
        _, thd = self._split(slots, xd)
        spin = self.gear_ratio * thd
        if self.coupling:
            w = _angular_velocities(robot, x[: robot.nq], xd[: robot.nq])
            carried = []
            for j in self.joints:
                p = robot.parents[j]
                if p < 0:  # a fixed base does not turn
                    carried.append(jnp.zeros((), dtype=xd.dtype))
                else:
                    # joint axis in the parent's axes does not depend on q_j (rotation about itself)
                    z = robot.placement_R[j] @ robot.axis[j]
                    carried.append(jnp.dot(z, w[p]))
            spin = spin + jnp.stack(carried)
        return 0.5 * jnp.sum(self.rotor_inertia * spin**2)

    def potential_energy(self, robot, slots: Slots, x):
        q, th = self._split(slots, x)
        d = q - th
        V = 0.5 * d @ (self._matrix(self.stiffness) @ d)
        if self.play is None:
            return V
        # the dead zone: the spring's energy less that of its clamp to [-b, b] (0 for b = 0)
        return V - jnp.sum(self.stiffness * _saturation_energy(d, self.play, self.play_smoothing))

    def spring_torque(self, robot, slots: Slots, x, xd):
        """Torque (m,) the transmission passes from motor to link, ``k dz(theta - q, b) +
        c (theta_dot - q_dot)`` (``K (theta - q) + B (theta_dot - q_dot)`` without play)."""
        qd, thd = self._split(slots, xd)
        # the elastic part is the derivative of potential_energy in the motor angles: the law is
        # stated once, as the energy
        x = jnp.asarray(x)
        el = jax.grad(lambda th: self.potential_energy(robot, slots, x.at[slots.coords].set(th)))(x[slots.coords])
        return el + self._matrix(self.damping) @ (thd - qd)

    def generalized_force(self, robot, slots: Slots, t, x, xd, z):
        idx = jnp.array(self.joints, dtype=int)
        qd, thd = self._split(slots, xd)
        joint = self._matrix(self.damping) @ (qd - thd)
        vs = self.coulomb_velocity
        f_link = -joint - self.link_viscous * qd - self.link_coulomb * _smooth_sign(qd, vs)
        f_motor = joint - self.motor_viscous * thd - self.motor_coulomb * _smooth_sign(thd, vs)
        f = jnp.zeros(slots.nx, dtype=xd.dtype).at[idx].add(f_link)
        return f.at[slots.coords].add(f_motor)

    def linear_force(self, robot, slots: Slots, t, x, xd, z):
        # small vibrations at rest: joint damping and viscous friction act, Coulomb friction sticks
        idx = jnp.array(self.joints, dtype=int)
        qd, thd = self._split(slots, xd)
        joint = self._matrix(self.damping) @ (qd - thd)
        f = jnp.zeros(slots.nx, dtype=xd.dtype).at[idx].add(-joint - self.link_viscous * qd)
        return f.at[slots.coords].add(joint - self.motor_viscous * thd)

    def actuation(self, robot, slots: Slots, B):
        idx = jnp.array(self.joints, dtype=int)
        rows = B[idx]
        return B.at[idx].set(0.0).at[slots.coords].set(rows)
