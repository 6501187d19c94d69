"""Checked inputs at the public boundary of the rigid-body algorithms.

Arguments known at trace time (NumPy, concrete JAX arrays) are checked in Python and a bad one
raises a :class:`jflex.DataError` or :class:`jflex.ParameterError` at once. Traced ones (inside
``jit``, ``vmap``, ``grad``) go through one ``eqx.error_if`` per call, which raises at run time
with the same message (an ``EqxRuntimeError`` / ``XlaRuntimeError``): a single ``isfinite(...).all()``
reduction and one conditional, whatever the batch.

Inside a batch program (:func:`jflex.batched`) the same checks are *collected* instead
(:func:`collecting`): each predicate becomes an output flag of the program and the host raises its
message after the call. An ``eqx.error_if`` is a callback from the compiled program into Python;
on a GPU every call would then hand control back to the host from inside the kernel.
"""

from __future__ import annotations

import contextvars

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._errors import DataError, ParameterError
from ._robot import PRISMATIC, Robot, check_q


def traced(a) -> bool:
    return isinstance(a, jax.core.Tracer)


# while a batch program is traced: the (predicate, message) pairs of its guards, in order
_COLLECTED: contextvars.ContextVar[list | None] = contextvars.ContextVar("jflex_collected_checks", default=None)


def guard(x, preds, msgs):
    """``x`` carrying a run-time check: raises ``msgs[k]`` for the first true ``preds[k]``
    (collected as flags instead while :func:`collecting` traces a batch program)."""
    if not preds:
        return x
    collected = _COLLECTED.get()
    if collected is not None:
        collected.extend((jnp.any(p), m) for p, m in zip(preds, msgs))
        return x
    if len(preds) == 1:
        return eqx.error_if(x, preds[0], msgs[0])
    bad = jnp.stack([jnp.any(p) for p in preds])
    return eqx.branched_error_if(x, jnp.any(bad), jnp.argmax(bad), msgs)


def collecting(fn, messages: list):
    """``fn`` returning ``(out, flags)``: ``flags[k]`` is the ``k``-th check of its guards (true:
    failed), whose message is appended to ``messages`` when ``fn`` is traced. Every trace of one
    program makes the same checks in the same order, so ``messages`` is filled once."""

    def item(*args):
        token = _COLLECTED.set([])
        try:
            out = fn(*args)
            found = _COLLECTED.get()
        finally:
            _COLLECTED.reset(token)
        if not messages:
            messages.extend(m for _, m in found)
        flags = jnp.stack([p for p, _ in found]) if found else jnp.zeros((0,), bool)
        return out, flags

    return item


def _check_concrete(fn: str, name: str, a) -> None:
    arr = np.asarray(a)
    if arr.dtype.kind not in "biufc":
        raise DataError(f"{fn}: {name} must be numbers, got an array of {arr.dtype} ({arr.ravel()[:3].tolist()}...)")
    if arr.dtype.kind in "fc" and not np.isfinite(arr).all():
        idx = np.flatnonzero(~np.isfinite(arr))
        raise DataError(
            f"{fn}: {name} contains NaN/inf (flat entries {idx[:6].tolist()} = {arr.ravel()[idx[:6]].tolist()}); "
            "the results would be NaN"
        )


def checked_arrays(fn: str, robot: Robot, **arrays):
    """The arguments as arrays, shape-checked ((n,) each; ``f_ext`` (n, 6)) and finite.

    ``fn`` names the public function in the messages, e.g. ``"rnea: q contains NaN/inf"``.
    """
    out, preds, msgs, first = [], [], [], None
    for name, a in arrays.items():
        if a is None:
            out.append(None)
            continue
        if not traced(a) and not isinstance(a, jax.Array):
            a = np.asarray(a)
        if name == "f_ext":
            if jnp.shape(a) != (robot.nq, 6):
                raise DataError(f"{fn}: f_ext must have shape ({robot.nq}, 6) (one [force; moment] per body), got {jnp.shape(a)}")
        else:
            check_q(robot, a, name)
        if traced(a):
            preds.append(~jnp.all(jnp.isfinite(a)))
            msgs.append(f"{fn}: {name} contains NaN/inf")
            first = len(out) if first is None else first
            out.append(a)
        else:
            _check_concrete(fn, name, a)
            out.append(jnp.asarray(a))
    if preds:
        out[first] = guard(out[first], preds, msgs)
    return out


def has_inertia(fn: str, robot: Robot) -> None:
    """A robot known at trace time whose every inertial parameter is zero has no dynamics: say so
    instead of returning zeros. (A traced robot, e.g. one being fitted, is not checked.)"""
    if traced(robot.inertia) or np.any(np.asarray(robot.inertia)):
        return
    raise ParameterError(
        f"{fn}: the robot (joints {list(robot.joint_names)}) has no inertial parameters: every link's mass and "
        "inertia is zero, so its dynamics are identically zero. Load a URDF with masses, give a YAML config "
        "`links:` (mass, com, inertia per link), or set robot.inertia (robot.replace(inertia=...)); kinematics "
        "(forward_kinematics, jacobian) and the regressor need none"
    )


def moving_inertia(fn: str, robot: Robot) -> None:
    """Raise :class:`ParameterError` naming the first joint that moves no inertia (its link and every
    link it carries have none: a zero row and column in the mass matrix), when the inertia is known
    at trace time. Revolute joints need any inertial parameter in their subtree, prismatic ones mass."""
    if traced(robot.inertia):
        return
    has_inertia(fn, robot)
    I = np.abs(np.asarray(robot.inertia))
    total, mass = I.sum(axis=1), I[:, 0].copy()
    for i in reversed(range(robot.nq)):
        p = robot.parents[i]
        if p >= 0:
            total[p] += total[i]
            mass[p] += mass[i]
    for i in range(robot.nq):
        moved = mass[i] if robot.joint_types[i] == PRISMATIC else total[i]
        if not moved > 0:
            what = "mass" if robot.joint_types[i] == PRISMATIC else "mass or inertia"
            raise ParameterError(
                f"{fn}: joint '{robot.joint_names[i]}' moves no inertia: link '{robot.link_names[i]}' and the links it "
                f"carries have zero {what}, so the mass matrix is singular. Give link '{robot.link_names[i]}' its "
                "inertial parameters (robot.inertia), or make its joint fixed"
            )
