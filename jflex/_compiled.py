"""One compiled program per robot and model structure for the un-jitted public analyses.

Called outside ``jit``, an analysis such as :func:`jflex.modal_analysis` would otherwise be traced
and dispatched op by op on every call (1-1.6 s a call for a 7-joint flexible-joint robot).
:func:`compiled` runs it through a cached ``equinox.filter_jit`` program instead, whose arguments
are the numbers that change from call to call (postures, inertial parameters, the effects'
parameters) and whose cache key is everything else: the topology, names, options and the
robot's kinematic constants (joint placements and axes, extra frames, gravity). Those constants
stay NumPy values inside the program, where the kernels fold their zeros and ones away (see
``jflex._tree.host``); traced, they made the Panda's linearisation program 2.5x larger and about
twice as slow to compile. So a second call at another posture, or on another model of the same
robot (other stiffness, damping, payload or inertial parameters), runs the compiled program;
another robot geometry compiles its own.

Called inside a caller's ``jit``, ``vmap`` or ``grad`` (any argument traced), the function is
traced inline as before, so numbers the caller closed over fold into the caller's program.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import numpy as np

from ._robot import Robot

# the robot's kinematic constants: part of a program's cache key, folded into the program
_KINEMATICS = ("placement_R", "placement_p", "axis", "gravity", "frame_R", "frame_p")


class _Constant:
    """A NumPy array compared and hashed by value: a static argument of a compiled program."""

    __slots__ = ("array", "_key")

    def __init__(self, a):
        self.array = np.asarray(a)
        self._key = (self.array.shape, self.array.dtype.str, self.array.tobytes())

    def __hash__(self):
        return hash(self._key)

    def __eq__(self, other):
        return isinstance(other, _Constant) and self._key == other._key


def _is_robot(x):
    return isinstance(x, Robot)


def _map_robots(fn, tree):
    return jax.tree_util.tree_map(lambda x: fn(x) if _is_robot(x) else x, tree, is_leaf=_is_robot)


def _fold(robot: Robot) -> Robot:
    for name in _KINEMATICS:
        if eqx.is_array(getattr(robot, name)):
            robot = eqx.tree_at(lambda r: getattr(r, name), robot, _Constant(getattr(robot, name)))
    return robot


def _unfold(robot: Robot) -> Robot:
    for name in _KINEMATICS:
        if isinstance(getattr(robot, name), _Constant):
            robot = eqx.tree_at(lambda r: getattr(r, name), robot, getattr(robot, name).array)
    return robot


# XLA options of a program whose compile time outweighs its run time: without LLVM's optimisation
# passes the flexible-joint Panda's un-jitted modal_analysis compiled in 4.1 s against 7.3 s on its
# first call, and later calls (about 10 ms, mostly dispatch) did not slow down (load 3 on 2 cores)
QUICK_COMPILE = {"xla_backend_optimization_level": 0}


def compiled(fn=None, *, compiler_options=None):
    """``fn`` through one compiled program per robot, model structure and static options.

    Array leaves of the arguments (except the robots' kinematic constants) are arguments of the
    program; every other leaf (strings, tuples, Python numbers) and the tree structure key its
    cache, so they must be hashable: arguments that are not fall back to a plain call, as do
    traced arguments (a call inside a caller's transformation is traced inline).
    ``compiler_options`` go to XLA (``jax.jit``'s)."""
    if fn is None:
        return functools.partial(compiled, compiler_options=compiler_options)
    program = eqx.filter_jit(lambda args, kwargs: fn(*_map_robots(_unfold, args), **_map_robots(_unfold, kwargs)),
                             **({"compiler_options": compiler_options} if compiler_options else {}))

    @functools.wraps(fn)
    def call(*args, **kwargs):
        leaves = jax.tree_util.tree_leaves((args, kwargs))
        if any(isinstance(leaf, jax.core.Tracer) for leaf in leaves):
            return fn(*args, **kwargs)
        try:
            args_, kwargs_ = _map_robots(_fold, (args, kwargs))
            hash(jax.tree_util.tree_structure((args_, kwargs_)))
            for leaf in jax.tree_util.tree_leaves((args_, kwargs_)):
                if not eqx.is_array(leaf):
                    hash(leaf)
        except TypeError:
            return fn(*args, **kwargs)
        return program(args_, kwargs_)

    return call
