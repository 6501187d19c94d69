"""Assumed-mode flexible links (seeds 001 and 004).

A beam clamped to a robot body bends in the plane spanned by the body axes ``axis`` (along the
beam) and ``bend`` (deflection). Its deflection is ``w(s, t) = sum_j phi_j(s / l) eta_j(t)``
with the shapes of :class:`jflex.Beam` (unit tip deflection), so the modal coordinates are in
metres. The effect owns the beam's energies, integrated by Gauss quadrature:

* kinetic: ``1/2 int rho A |v|^2 ds + 1/2 int rho I Omega^2 ds`` (+ tip mass and inertia), the
  velocity of each material point obtained by a jvp of its world position, so the rigid motion
  of the body, the deflection and their coupling all come out of one expression and the
  equations of motion follow by automatic differentiation of the Lagrangian (see
  :mod:`jflex._model`);
* potential: strain ``EI / (2 l^3) int (phi'' eta)^2 dxi`` and gravity.

**Who carries the rigid mass.** With ``include_rigid=True`` (default) the effect's energies
include the rigid motion of the beam: the robot's link must then hold only the hub / rigid
parts (give it zero beam mass). With ``include_rigid=False`` the effect adds only the increment
``E(x) - E(x with modal coordinates and rates set to 0)``, and the robot's link holds the beam
as a rigid body; this is the natural choice for a link sliding through a prismatic hub
(``sliding_joint``), whose rigid inertia the prismatic body already carries.

**Sliding link** (as in "Analytical and experimental investigation of the dynamic behavior of a revolute-prismatic manipulator with N flexible links and hubs"). With ``sliding_joint`` the free length is
``l = beam.length + q[sliding_joint]`` (the joint coordinate is the extension), the shapes scale
with ``l`` (time-varying mode shapes) and material points flow outward at ``dl/dt``: each
point is labelled by its distance from the free end, which is what the jvp holds fixed.

**Flexible hub** (same source). With ``hub`` (a :class:`jflex.Beam`) the hub is itself a clamped
beam from ``root``; the link is clamped at the hub tip and rotated by the hub's tip slope. The
part of the link inside the hub is carried rigidly by the robot and does not follow the hub's
deflection (a simplification).

Damping: ``air`` [kg/(s m)] is a distributed viscous force on the deflection rate;
``damping`` / ``hub_damping`` a damping law (Kelvin-Voigt, fractional, hysteretic) on the modal
coordinates with the beam's stiffness; a hysteretic law acts on the tip deflection.

**Foreshortening (``foreshortening=True``, default off).** A beam that bends without
stretching (inextensible neutral axis) draws its points towards the clamp: the point at arc
length ``s`` from the clamp moves axially by

    u(s) = -1/2 int_0^s w'(r)^2 dr = -1/(2 l) eta^T S(s / l) eta,
    S_ij(xi) = int_0^xi phi_i'(t) phi_j'(t) dt,

with ``phi'`` the derivative in the unit-length variable and ``l`` the current free length (so
a sliding link's time-varying length enters too), ``u`` evaluated by the beam's Gauss rule
mapped onto ``[0, xi]`` for every station. The point positions of the kinetic energy and of the
gravity potential carry ``u``, so the axial load of the rigid motion stiffens the bending by
itself: centrifugal stiffening of a spinning beam (for this in-plane bending, Southwell's
``omega^2 = omega_0^2 + (K_1 - 1) Omega^2``, ``K_1 = 1.193`` for the first mode), gravity
stiffening of a hanging beam and softening of a standing one, with the matching Coriolis and
axial-inertia couplings. It applies to a flexible hub as well (its tip, the link's clamp,
moves in by ``u_h(L_h)``). The strain energy stays the linear bending energy: the model is
consistent to second order in the deflection (axial strain, higher-order shortening and the
nonlinear curvature are neglected), which is what small-vibration frequencies and moderate
deflections (``|w'| << 1``) need. Without the option a point keeps its axial position ``s``:
the rotating beam then has only the in-plane softening, ``omega^2 = omega_0^2 - Omega^2``,
acceptable only while ``Omega^2`` (or ``g / l``) is small against ``omega_0^2``.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._beam import Beam
from .._errors import ParameterError, ShapeError
from .._tree import body_placement
from ._base import AbstractEffect, Slots
from ._damping import AbstractDampingLaw


class FlexibleLink(AbstractEffect):
    """An assumed-mode beam clamped to a robot body (see the module docstring).

    **Arguments:** ``body`` (link, joint or frame name the beam is clamped to; static);
    ``beam`` (:class:`jflex.Beam`); ``root`` (3,) [m] clamp point in that frame; ``axis``,
    ``bend`` body-axis indices (0, 1, 2) along the beam and of the deflection (static);
    ``name`` output/coordinate prefix; ``sliding_joint`` prismatic joint whose coordinate extends
    the free length; ``hub`` optional flexible hub :class:`jflex.Beam`; ``air`` [kg/(s m)];
    ``damping``, ``hub_damping`` damping laws; ``thickness`` [m] (for strain outputs);
    ``include_rigid`` (static); ``foreshortening`` (static) adds the quadratic axial shortening
    of the bent beam to the point positions (geometric stiffening, see the module docstring).
    """

    beam: Beam
    root: jnp.ndarray
    air: jnp.ndarray
    thickness: jnp.ndarray
    damping: AbstractDampingLaw | None
    hub: Beam | None
    hub_damping: AbstractDampingLaw | None
    body: str = eqx.field(static=True)
    name: str = eqx.field(static=True)
    axis: int = eqx.field(static=True)
    bend: int = eqx.field(static=True)
    sliding_joint: str | None = eqx.field(static=True)
    include_rigid: bool = eqx.field(static=True)
    foreshortening: bool = eqx.field(static=True)

    def __init__(self, body, beam: Beam, *, root=(0.0, 0.0, 0.0), axis: int = 0, bend: int = 1, name: str = "beam",
                 sliding_joint=None, hub: Beam | None = None, air=0.0, damping=None, hub_damping=None,
                 thickness=0.0, include_rigid: bool = True, foreshortening: bool = False):
        if axis == bend or axis not in (0, 1, 2) or bend not in (0, 1, 2):
            raise ParameterError(f"FlexibleLink '{name}': axis and bend must be different body-axis indices 0-2, got {axis}, {bend}")
        root = np.asarray(root, dtype=float)
        if root.shape != (3,):
            raise ShapeError(f"FlexibleLink '{name}'.root: expected 3 numbers [m], got shape {root.shape}")
        if float(air) < 0:
            raise ParameterError(f"FlexibleLink '{name}'.air must be >= 0 [kg/(s m)], got {air}")
        if float(thickness) < 0:
            raise ParameterError(f"FlexibleLink '{name}'.thickness must be >= 0 [m], got {thickness}")
        if hub is not None and sliding_joint is None and False:
            pass
        self.body, self.beam, self.root, self.axis, self.bend, self.name = body, beam, jnp.asarray(root), axis, bend, name
        self.sliding_joint, self.hub, self.air, self.damping = sliding_joint, hub, jnp.asarray(float(air)), damping
        self.hub_damping, self.thickness, self.include_rigid = hub_damping, jnp.asarray(float(thickness)), include_rigid
        self.foreshortening = bool(foreshortening)

    # ---- bookkeeping -------------------------------------------------------------------
    @property
    def m(self):
        return self.beam.n_modes

    @property
    def mh(self):
        return 0 if self.hub is None else self.hub.n_modes

    def coord_names(self, robot):
        hub = tuple(f"{self.name}.hub_eta{j + 1}" for j in range(self.mh))
        return hub + tuple(f"{self.name}.eta{j + 1}" for j in range(self.m))

    def _laws(self):
        return [(self.hub_damping, self.mh, "hub"), (self.damping, self.m, "link")]

    def state_names(self, robot):
        out = []
        for law, m, tag in self._laws():
            if law is not None and m:
                r = 1 if tag == "link" or True else m
                out += [f"{self.name}.{tag}.{s}" for s in law.state_suffixes(m, r)]
        return tuple(out)

    def initial_state(self, robot, slots: Slots):
        parts = [law.initial_state(m, 1) for law, m, _ in self._laws() if law is not None and m]
        return jnp.concatenate(parts) if parts else jnp.zeros(0)

    def _split_states(self, z):
        out, k = {}, 0
        for law, m, tag in self._laws():
            if law is not None and m:
                ns = len(law.state_suffixes(m, 1))
                out[tag] = z[k:k + ns]
                k += ns
        return out

    def _body(self, robot):
        b, k = robot.frame_index(self.body)
        if b < 0:
            raise ShapeError(f"FlexibleLink '{self.name}': body '{self.body}' is the base; clamp the beam to a moving body")
        if robot.joint_types[b] == "prismatic" and self.sliding_joint is not None:
            pass
        if self.sliding_joint is not None:
            if self.sliding_joint not in robot.joint_names:
                raise ShapeError(f"FlexibleLink '{self.name}': unknown sliding_joint '{self.sliding_joint}'; joints: {list(robot.joint_names)}")
            if robot.joint_types[robot.joint_names.index(self.sliding_joint)] != "prismatic":
                raise ShapeError(f"FlexibleLink '{self.name}': sliding_joint '{self.sliding_joint}' must be prismatic")
        return b, k

    def _coords(self, slots: Slots, x):
        c = x[slots.coords]
        return c[: self.mh], c[self.mh:]

    def _length(self, robot, x):
        if self.sliding_joint is None:
            return self.beam.length
        return self.beam.length + x[robot.joint_names.index(self.sliding_joint)]

    def _units(self):
        e = jnp.eye(3)
        return e[self.axis], e[self.bend], jnp.cross(e[self.axis], e[self.bend])

    # ---- geometry ------------------------------------------------------------------------
    def _shortening(self, beam: Beam, xi, eta, l):
        """Axial displacement ``u = -1/(2 l) int_0^xi (phi'(t) . eta)^2 dt`` [m] (shape of ``xi``)
        of the stations ``xi`` of a beam of current length ``l``; 0 without foreshortening.
        Gauss rule of the beam mapped onto each ``[0, xi]``."""
        xi = jnp.asarray(xi)
        if not self.foreshortening:
            return jnp.zeros(xi.shape)
        xq, wq = beam.quadrature()
        d1 = beam.shapes(xi[..., None] * jnp.asarray(xq))[1]  # (..., nq, m)
        return -0.5 / l * xi * ((d1 @ eta) ** 2 @ jnp.asarray(wq))

    def _clamp(self, slots, x):
        """Clamp point (3,) and rotation psi of the link beam in body axes."""
        ea, eb, _ = self._units()
        if self.hub is None:
            return self.root, jnp.zeros(())
        eh, _ = self._coords(slots, x)
        p, d1, _ = self.hub.shapes(1.0)
        Lh = self.hub.length
        uh = self._shortening(self.hub, 1.0, eh, Lh)
        return self.root + (Lh + uh) * ea + (p @ eh) * eb, (d1 @ eh) / Lh

    def _link_point(self, robot, slots, x, a):
        """Body-frame positions (..., 3) and cross-section rotations (...) of the link points at
        distances ``a`` (...) from the free end (material labels)."""
        ea, eb, _ = self._units()
        _, eta = self._coords(slots, x)
        l = self._length(robot, x)
        s = l - a
        p, d1, _ = self.beam.shapes(s / l)
        w, slope = p @ eta, (d1 @ eta) / l
        sa = s + self._shortening(self.beam, s / l, eta, l)  # axial position along the clamp axis
        c, psi = self._clamp(slots, x)
        cs, sn = jnp.cos(psi), jnp.sin(psi)
        r = c + (sa * cs - w * sn)[..., None] * ea + (sa * sn + w * cs)[..., None] * eb
        return r, psi + slope

    def _hub_point(self, slots, x, s):
        ea, eb, _ = self._units()
        eh, _ = self._coords(slots, x)
        Lh = self.hub.length
        p, d1, _ = self.hub.shapes(s / Lh)
        sa = s + self._shortening(self.hub, s / Lh, eh, Lh)
        return self.root + sa[..., None] * ea + (p @ eh)[..., None] * eb, (d1 @ eh) / Lh

    def _placement(self, robot, slots, x):
        """World rotation and position of the body the beam is clamped to."""
        return body_placement(robot, x[: slots.n], self._body(robot)[0])

    def _to_world(self, robot, placement, r):
        _, k = self._body(robot)
        R, p = placement
        if k >= 0:
            p = p + R @ robot.frame_p[k]
            R = R @ robot.frame_R[k]
        return p + r @ R.T

    def _sample(self, robot, slots, x, labels, hub_s):
        """World positions and rotations of the link points (labels), the tip and the hub points, and
        the world rotation of the body the beam is clamped to."""
        pl = self._placement(robot, slots, x)
        a = jnp.concatenate([labels, jnp.zeros(1)])  # the tip is the last point
        r, th = self._link_point(robot, slots, x, a)
        P = self._to_world(robot, pl, r)
        if self.hub is not None:
            rh, THh = self._hub_point(slots, x, hub_s)
            Ph = self._to_world(robot, pl, rh)
        else:
            Ph, THh = jnp.zeros((0, 3)), jnp.zeros(0)
        return P[:-1], th[:-1], P[-1], th[-1], Ph, THh, pl[0]

    # ---- energies -------------------------------------------------------------------------
    def _zero_modes(self, slots, v):
        return v.at[slots.coords].set(0.0)

    def _T(self, robot, slots, x, xd):
        xi, wq = self.beam.quadrature()
        l = self._length(robot, x)
        labels = (1.0 - jnp.asarray(xi)) * l
        hub_s, hw = (None, None)
        if self.hub is not None:
            hx, hw = self.hub.quadrature()
            hub_s = jnp.asarray(hx) * self.hub.length
        f = lambda y: self._sample(robot, slots, y, labels, hub_s)
        # (the clamp body's rotation and its rate come with the points': one JVP of the placement)
        (*_, R), (V, THd, Vt, THdt, Vh, THdh, Rd) = jax.jvp(f, (x,), (xd,))
        _, _, en = self._units()
        W = R.T @ Rd  # [w]x of the body's angular velocity in its own axes
        wn = jnp.stack([W[2, 1], W[0, 2], W[1, 0]]) @ en  # rotation rate about the bending normal, same in body and world
        bm = self.beam
        w = jnp.asarray(wq)
        T = 0.5 * bm.mass_per_length * l * (w @ jnp.sum(V**2, axis=1))
        T = T + 0.5 * bm.rotary_inertia * l * (w @ (wn + THd) ** 2)
        T = T + 0.5 * bm.tip_mass * (Vt @ Vt) + 0.5 * bm.tip_inertia * (wn + THdt) ** 2
        if self.hub is not None:
            hb, w2 = self.hub, jnp.asarray(hw)
            T = T + 0.5 * hb.mass_per_length * hb.length * (w2 @ jnp.sum(Vh**2, axis=1))
            T = T + 0.5 * hb.rotary_inertia * hb.length * (w2 @ (wn + THdh) ** 2)
        return T

    def _V(self, robot, slots, x):
        xi, wq = self.beam.quadrature()
        l = self._length(robot, x)
        eh, eta = self._coords(slots, x)
        w = jnp.asarray(wq)
        d2 = self.beam.shapes(jnp.asarray(xi))[2]
        V = 0.5 * self.beam.EI / l**3 * (w @ (d2 @ eta) ** 2)
        labels = (1.0 - jnp.asarray(xi)) * l
        hub_s = None
        if self.hub is not None:
            hx, hw = self.hub.quadrature()
            hub_s = jnp.asarray(hx) * self.hub.length
            d2h = self.hub.shapes(jnp.asarray(hx))[2]
            V = V + 0.5 * self.hub.EI / self.hub.length**3 * (jnp.asarray(hw) @ (d2h @ eh) ** 2)
        P, _, Pt, _, Ph, _, _ = self._sample(robot, slots, x, labels, hub_s)
        g = robot.gravity
        V = V - self.beam.mass_per_length * l * (w @ (P @ g)) - self.beam.tip_mass * (Pt @ g)
        if self.hub is not None:
            V = V - self.hub.mass_per_length * self.hub.length * (jnp.asarray(hw) @ (Ph @ g))
        return V

    def kinetic_energy(self, robot, slots: Slots, x, xd):
        T = self._T(robot, slots, x, xd)
        if not self.include_rigid:
            T = T - self._T(robot, slots, self._zero_modes(slots, x), self._zero_modes(slots, xd))
        return T

    def potential_energy(self, robot, slots: Slots, x):
        V = self._V(robot, slots, x)
        if not self.include_rigid:
            V = V - self._V(robot, slots, self._zero_modes(slots, x))
        return V

    # ---- damping ------------------------------------------------------------------------
    def stiffness(self, robot, x):
        """Modal stiffness matrices ``(K_hub (mh, mh), K_link (m, m))`` [N/m] at the current length."""
        l = self._length(robot, x)
        xi, wq = self.beam.quadrature()
        d2 = self.beam.shapes(jnp.asarray(xi))[2]
        K = self.beam.EI / l**3 * (d2.T * jnp.asarray(wq)) @ d2
        if self.hub is None:
            return jnp.zeros((0, 0)), K
        hx, hw = self.hub.quadrature()
        d2h = self.hub.shapes(jnp.asarray(hx))[2]
        return self.hub.EI / self.hub.length**3 * (d2h.T * jnp.asarray(hw)) @ d2h, K

    def _P(self, beam):
        return beam.shapes(1.0)[0][None, :]

    def generalized_force(self, robot, slots: Slots, t, x, xd, z):
        eh, eta = self._coords(slots, x)
        ehd, etad = self._coords(slots, xd)
        Kh, K = self.stiffness(robot, x)
        l = self._length(robot, x)
        xi, wq = self.beam.quadrature()
        phi = self.beam.shapes(jnp.asarray(xi))[0]
        Q_link = -self.air * l * (phi.T * jnp.asarray(wq)) @ (phi @ etad)
        Q_hub = jnp.zeros(self.mh)
        zs = self._split_states(z[slots.states])
        if self.damping is not None:
            Q_link = Q_link - self.damping.force(K, eta, etad, zs["link"], self._P(self.beam))
        if self.hub_damping is not None and self.mh:
            Q_hub = Q_hub - self.hub_damping.force(Kh, eh, ehd, zs["hub"], self._P(self.hub))
        return jnp.zeros(slots.nx).at[slots.coords].set(jnp.concatenate([Q_hub, Q_link]))

    def state_rate(self, robot, slots: Slots, t, x, xd, z):
        eh, eta = self._coords(slots, x)
        ehd, etad = self._coords(slots, xd)
        Kh, K = self.stiffness(robot, x)
        zs = self._split_states(z[slots.states])
        parts = []
        if self.hub_damping is not None and self.mh:
            parts.append(self.hub_damping.state_rate(Kh, eh, ehd, zs["hub"], self._P(self.hub)))
        if self.damping is not None:
            parts.append(self.damping.state_rate(K, eta, etad, zs["link"], self._P(self.beam)))
        return jnp.concatenate(parts) if parts else jnp.zeros(0)

    def dynamic_stiffness(self, robot, slots: Slots, x0, omega):
        Kh, K = self.stiffness(robot, x0)
        D = jnp.zeros((slots.nx, slots.nx), complex)
        a, b = slots.coords.start, slots.coords.stop
        any_term = False
        if self.hub_damping is not None and self.mh:
            t = self.hub_damping.frequency_term(Kh, omega, self._P(self.hub))
            if t is not None:
                D, any_term = D.at[a:a + self.mh, a:a + self.mh].add(t), True
        if self.damping is not None:
            t = self.damping.frequency_term(K, omega, self._P(self.beam))
            if t is not None:
                D, any_term = D.at[a + self.mh:b, a + self.mh:b].add(t), True
        return D if any_term else None

    # ---- outputs ------------------------------------------------------------------------
    def output(self, robot, slots: Slots, name, x, xd, z):
        pre = self.name + "."
        if not name.startswith(pre):
            return None
        key = name[len(pre):]
        eh, eta = self._coords(slots, x)
        _, eb, _ = self._units()
        if key == "tip_deflection":  # lateral offset of the tip from the undeformed line, body axes
            r, _ = self._link_point(robot, slots, x, jnp.zeros(()))
            return (r - self.root) @ eb
        if key == "link_tip_deflection":
            return self.beam.shapes(1.0)[0] @ eta
        if key == "hub_tip_deflection":
            return self.hub.shapes(1.0)[0] @ eh if self.hub is not None else jnp.zeros(())
        if key == "length":
            return self._length(robot, x)
        if key == "tip_position":
            return self._to_world(robot, self._placement(robot, slots, x), self._link_point(robot, slots, x, jnp.zeros(()))[0])
        for kind in ("deflection@", "curvature@", "strain@"):
            if key.startswith(kind):
                try:
                    s = float(key[len(kind):])
                except ValueError:
                    raise ShapeError(f"output '{name}': expected a station in metres after '@', e.g. '{pre}{kind}0.2'") from None
                l = self._length(robot, x)
                p, _, d2 = self.beam.shapes(jnp.clip(s / l, 0.0, 1.0))
                if kind == "deflection@":
                    return p @ eta
                kappa = (d2 @ eta) / l**2
                # bending strain on the surface on the +bend side: -t/2 w''
                return kappa if kind == "curvature@" else -0.5 * self.thickness * kappa
        return None
