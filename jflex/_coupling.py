"""Coupled (mimic) joints: a robot's coordinates ``q`` (nq) mapped onto its tree's joints (n).

A joint that mimics a leader moves at ``q_i = a_i q_k + b_i`` (a URDF's ``<mimic>``), so the
tree's joint values are ``q_full = G q + b`` with ``G`` (n, nq) holding a 1 per independent joint
and ``a_i`` per coupled one; rates follow ``qd_full = G qd`` and ``qdd_full = G qdd``. By virtual
work the generalised forces are ``tau = G^T tau_full``, the mass matrix ``G^T M_full G``, a
Jacobian ``J_full G`` (Pinocchio's ``JointModelMimic`` gives the same). The algorithms run on the
uncoupled tree (:func:`tree`) between :func:`positions` and :func:`project`; for a robot without
coupled joints none of this is called, so its traced programs stay as they were.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from ._checks import checked_arrays
from ._robot import Robot


def host(a):
    return a if isinstance(a, jax.core.Tracer) else np.asarray(a)


def coupled(robot: Robot) -> bool:
    """Whether the robot has coupled joints (static)."""
    return bool(robot.mimic)


def tree(robot: Robot) -> Robot:
    """The same tree with every joint independent (n coordinates)."""
    return dataclasses.replace(robot, mimic=(), mimic_multiplier=None, mimic_offset=None)


def coordinate_index(robot: Robot) -> np.ndarray:
    """For each joint of the tree, the coordinate it moves with (its own, or its leader's)."""
    own = np.cumsum([k < 0 for k in robot.mimic]) - 1
    return np.array([own[i] if k < 0 else own[k] for i, k in enumerate(robot.mimic)])


def matrix(robot: Robot):
    """``G`` (n, nq): ``q_full = G q + b``."""
    n = robot.n_joints
    a = jnp.where(np.array(robot.mimic) >= 0, host(robot.mimic_multiplier), 1.0)
    return jnp.zeros((n, robot.nq), dtype=a.dtype).at[np.arange(n), coordinate_index(robot)].set(a)


def _gather(robot: Robot, x):
    a = jnp.where(np.array(robot.mimic) >= 0, host(robot.mimic_multiplier), 1.0)
    return jnp.asarray(x)[coordinate_index(robot)] * a


def positions(robot: Robot, q):
    """The tree's joint values ``G q + b`` (n,)."""
    b = jnp.where(np.array(robot.mimic) >= 0, host(robot.mimic_offset), 0.0)
    return _gather(robot, q) + b


def rates(robot: Robot, qd):
    """The tree's joint rates ``G qd`` (n,) (velocities, accelerations)."""
    return _gather(robot, qd)


def project(robot: Robot, f):
    """``G^T f``: generalised forces of the coordinates from the tree's joint forces; on the first
    axis of ``f`` (n, ...)."""
    return jnp.tensordot(matrix(robot).T, f, axes=1)


def checked(fn: str, robot: Robot, **arrays):
    """:func:`._checks.checked_arrays` with ``f_ext`` (last) checked against the tree's joints
    (one wrench per body) when the robot has coupled joints."""
    if not coupled(robot) or arrays.get("f_ext") is None:
        return checked_arrays(fn, robot, **arrays)
    f_ext = arrays.pop("f_ext")
    out = checked_arrays(fn, robot, **arrays)
    return [*out, *checked_arrays(fn, tree(robot), f_ext=f_ext)]
