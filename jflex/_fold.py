"""Compiled programs with a model's robot kinematics folded in as constants.

The scalarised kernels (:mod:`jflex._scalar`) drop every product with a known 0 or 1, but only
for numbers known while tracing. A model passed to a compiled function as an argument is traced
whole, so a URDF's right-angle placements and unit axes cost their full arithmetic: a 3-joint
arm's forward dynamics with flexible joints took 2822 operations traced, 1425 with its
placements, axes, gravity and frames known. :func:`fold_kinematics` compiles a function of a
model with those known and everything else (inertias, limits, every effect) traced, so that
models differing only in their physical numbers share one program.
"""

from __future__ import annotations

from typing import Callable

import equinox as eqx
import jax
import numpy as np

KINEMATICS = ("placement_R", "placement_p", "axis", "gravity", "frame_R", "frame_p")
_MAX_PROGRAMS = 8  # robots (kinematics) kept per function


def fold_kinematics(fn: Callable) -> Callable:
    """``fn(model, *args)`` as a compiled function (:func:`equinox.filter_jit`: arrays traced,
    other arguments static) whose model's robot kinematics (:data:`KINEMATICS`) are constants
    of the program: one program per distinct kinematics (the arrays' bytes and the robot's
    static structure), at most :data:`_MAX_PROGRAMS` kept."""
    programs: dict = {}

    def call(model, *args, **kwargs):
        robot = model.robot
        if any(isinstance(getattr(robot, f), jax.core.Tracer) for f in KINEMATICS):
            return fn(model, *args, **kwargs)  # already inside a trace: nothing to fold
        known = {f: np.asarray(getattr(robot, f)) for f in KINEMATICS}
        key = (jax.tree_util.tree_structure(robot),) + tuple((a.shape, a.tobytes()) for a in known.values())
        program = programs.get(key)
        if program is None:
            def with_known(model, *args, **kwargs):
                # NumPy leaves, not Robot.replace's jnp.asarray: that would be traced again here
                robot = eqx.tree_at(lambda r: [getattr(r, f) for f in KINEMATICS], model.robot, list(known.values()))
                return fn(eqx.tree_at(lambda m: m.robot, model, robot), *args, **kwargs)

            with_known.__name__ = with_known.__qualname__ = getattr(fn, "__name__", "folded")  # compile logs
            program = programs[key] = eqx.filter_jit(with_known)
            if len(programs) > _MAX_PROGRAMS:
                programs.pop(next(iter(programs)))
        return program(model, *args, **kwargs)

    call.__wrapped__ = fn
    call.__doc__ = fn.__doc__
    call.__name__ = getattr(fn, "__name__", "folded")
    return call
