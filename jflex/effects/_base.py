"""The effect interface: what an effect adds to the rigid core of a :class:`jflex.Model`.

A model is a rigid robot plus effects. The generalised coordinates of a model are
``x = [q (robot joints), coordinates of effect 1, coordinates of effect 2, ...]`` and its
internal first-order states are ``z = [states of effect 1, ...]`` (fractional filter states,
hysteresis memory, ...). The equations of motion are Lagrange's,

$$ M(x)\\ddot x + h(x, \\dot x) = B u + \\sum_e f_e(t, x, \\dot x, z), \\qquad \\dot z = g(t, x, \\dot x, z), $$

where the rigid robot contributes through CRBA/RNEA and each effect through its kinetic energy
$T_e(x, \\dot x)$, potential energy $V_e(x)$ (differentiated automatically), and non-conservative
generalised force $f_e$. Every analysis (simulation, linearisation, FRFs, identification, gap
diagnosis) goes through these methods only; an analysis never asks for an effect's type.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp

from .._errors import ShapeError


class Slots(NamedTuple):
    """Where an effect's pieces sit in the model vectors (static, hashable).

    ``n`` is the number of robot joints (``x[:n]`` is q); ``coords`` is the slice of ``x`` holding
    this effect's own coordinates; ``states`` the slice of ``z`` holding its internal states;
    ``nx`` and ``nz`` the total sizes.
    """

    n: int
    coords: slice
    states: slice
    nx: int
    nz: int


class AbstractEffect(eqx.Module):
    """Interface of an effect. Every method has a neutral default, so an effect overrides only
    what it adds. ``robot`` is the (possibly modified) rigid :class:`jflex.Robot` of the model.
    """

    def modify_robot(self, robot):
        """Return the rigid robot this effect implies (e.g. a payload adds mass). Default: unchanged."""
        return robot

    def coord_names(self, robot) -> tuple[str, ...]:
        """Names of the extra generalised coordinates this effect adds (static)."""
        return ()

    def state_names(self, robot) -> tuple[str, ...]:
        """Names of the internal first-order states this effect adds (static)."""
        return ()

    def initial_state(self, robot, slots: Slots):
        """Initial internal states, shape (len(state_names),)."""
        return jnp.zeros(len(self.state_names(robot)))

    def coords_at_posture(self, robot, slots: Slots, q):
        """This effect's coordinates when the robot rests at joint posture ``q`` (n,) with its
        elastic elements unloaded (e.g. motor angles equal to link angles); used to expand a
        posture into a full x0 for linearisation. Default: zeros."""
        return jnp.zeros(len(self.coord_names(robot)))

    def kinetic_energy(self, robot, slots: Slots, x, xd):
        """Extra kinetic energy [J] (rotor inertia, link deformation, ...). Default 0."""
        return jnp.zeros(())

    def potential_energy(self, robot, slots: Slots, x):
        """Extra potential energy [J] (springs, strain energy, ...). Default 0."""
        return jnp.zeros(())

    def generalized_force(self, robot, slots: Slots, t, x, xd, z):
        """Non-conservative generalised force on x, shape (nx,) (friction, damping). Default 0."""
        return jnp.zeros(slots.nx)

    def linear_force(self, robot, slots: Slots, t, x, xd, z):
        """The part of ``generalized_force`` that acts in small vibrations about a posture at rest,
        used by the linearisation. Default: all of it. Friction laws leave out Coulomb terms,
        which stick at rest rather than act as a steep viscous damper."""
        return self.generalized_force(robot, slots, t, x, xd, z)

    def state_rate(self, robot, slots: Slots, t, x, xd, z):
        """Time derivative of this effect's internal states, shape (len(state_names),)."""
        return jnp.zeros(len(self.state_names(robot)))

    def actuation(self, robot, slots: Slots, B):
        """Return the input matrix (nx, nu) after this effect (a flexible joint moves its actuator
        from the link coordinate to the motor coordinate). Default: unchanged."""
        return B

    def output(self, robot, slots: Slots, name: str, x, xd, z):
        """Value of the named output ``name`` (e.g. ``"beam.tip_deflection"``,
        ``"beam.strain@0.3"``) at one state, or ``None`` when this effect does not provide it.
        Used by :func:`jflex.simulate` to resolve output names. Default: provides nothing."""
        return None

    def dynamic_stiffness(self, robot, slots: Slots, x0, omega):
        """Frequency-domain contribution to the dynamic stiffness at ``omega`` [rad/s], complex
        (nx, nx), for effects whose time-domain force is not a plain function of (x, xd)
        (fractional, hysteretic). ``None`` (default) means: use the linearisation of
        ``generalized_force``, i.e. ``-df/dx - i omega df/dxd``."""
        return None


def joint_indices(robot, joints, who: str) -> tuple[int, ...]:
    """Indices (static) of ``joints``, names or indices, in ``robot``; ``who`` names the effect in
    the error for an unknown name or an index out of range."""
    out = []
    for j in joints:
        if isinstance(j, str):
            if j not in robot.joint_names:
                raise ShapeError(f"{who}: unknown joint '{j}'; joints: {list(robot.joint_names)}")
            out.append(robot.joint_names.index(j))
        else:
            if not 0 <= int(j) < robot.nq:
                raise ShapeError(f"{who}: joint index {int(j)} out of range for a robot with {robot.nq} joints")
            out.append(int(j))
    return tuple(out)
