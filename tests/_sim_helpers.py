"""Small sample systems shared by the simulation tests (kept tiny: jit compile is the cost)."""

import jax.numpy as jnp
import numpy as np

import jflex
from jflex.effects import AbstractEffect


class Spring(AbstractEffect):
    """Test-only linear spring 1/2 k x_i^2 on coordinate ``i`` (independent of library springs)."""

    k: jnp.ndarray
    i: int = 0

    def potential_energy(self, robot, slots, x):
        return 0.5 * self.k * x[self.i] ** 2


def slider(mass=1.0, gravity=(0.0, 0.0, 0.0)):
    """One prismatic joint along x carrying a point mass [kg]."""
    return jflex.make_robot(
        joint_names=["j"], link_names=["body"], parents=[-1], joint_types=["prismatic"],
        placement_R=np.eye(3)[None], placement_p=np.zeros((1, 3)), axis=[[1.0, 0, 0]],
        inertia=np.array([[mass, 0, 0, 0, 0, 0, 0, 0, 0, 0]]), gravity=gravity,
    )


def rotor(inertia=0.1, gravity=(0.0, 0.0, 0.0)):
    """One revolute joint about z carrying a hub of inertia ``inertia`` [kg m^2]."""
    return jflex.make_robot(
        joint_names=["j1"], link_names=["hub"], parents=[-1], joint_types=["revolute"],
        placement_R=np.eye(3)[None], placement_p=np.zeros((1, 3)), axis=[[0, 0, 1.0]],
        inertia=np.array([[1.0, 0, 0, 0, inertia, 0, inertia, 0, 0, inertia]]), gravity=gravity,
    )


def oscillator(m=1.0, k=100.0, c=0.0):
    """m xdd + c xd + k x = u."""
    return jflex.Model(slider(m), [Spring(jnp.asarray(k)), jflex.effects.ViscousDamping((0,), [c])])
