"""Shared plumbing of the linear analyses: postures, held coordinates, tool Jacobians, checks."""

from __future__ import annotations

import fnmatch

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._dynamics import jacobian
from .._errors import ParameterError, ShapeError
from .._model import Model, input_matrix, linearize
from .._simulate import effect_output


def expand_posture(model: Model, posture):
    """Full coordinates x0 (nx,) from a robot posture q (n,) or from x0 itself (nx,).

    A posture of length n is completed with each effect's ``coords_at_posture`` (motor angles
    equal to link angles for flexible joints).
    """
    x = jnp.asarray(posture)
    r, lay = model.rigid, model.layout
    if x.shape == (lay.nx,):
        return x
    if x.shape != (r.nq,):
        raise ShapeError(
            f"posture must have shape ({r.nq},) (robot joints {list(r.joint_names)}) or ({lay.nx},) "
            f"(all coordinates {list(lay.coord_names)}), got {x.shape}; batch with jax.vmap or jflex.sweep"
        )
    parts = [x] + [jnp.asarray(e.coords_at_posture(r, s, x), dtype=x.dtype) for e, s in zip(model.effects, lay.slots)]
    return jnp.concatenate(parts)


def resolve_hold(model: Model, hold) -> tuple[str, ...]:
    """Names of the held coordinates.

    ``hold`` is ``"actuated"`` (every coordinate an actuator drives: perfect position control,
    seed 003's assumption), a name or glob pattern (``"theta_*"``), an index, or a sequence of
    those; ``()`` or ``None`` holds nothing.
    """
    names = model.layout.coord_names
    if hold is None:
        return ()
    if isinstance(hold, (str, int, np.integer)):
        hold = (hold,)
    out: list[str] = []
    for h in hold:
        if isinstance(h, (int, np.integer)):
            if not 0 <= int(h) < len(names):
                raise ShapeError(f"hold: coordinate index {h} out of range; coordinates: {list(names)}")
            out.append(names[int(h)])
        elif h == "actuated":
            try:
                with jax.ensure_compile_time_eval():
                    B = np.asarray(input_matrix(model))
            except jax.errors.ConcretizationTypeError:
                raise ShapeError("hold='actuated' needs a structural input matrix; name the coordinates instead") from None
            out += [names[i] for i in np.flatnonzero(np.abs(B).sum(axis=1) > 0)]
        else:
            hits = [n for n in names if fnmatch.fnmatchcase(n, str(h))]
            if not hits:
                raise ShapeError(f"hold: '{h}' matches no coordinate; coordinates: {list(names)}")
            out += hits
    keep = [n for n in names if n not in out]
    if not keep:
        raise ShapeError(f"hold: holding {sorted(set(out))} leaves no free coordinate (coordinates {list(names)})")
    return tuple(dict.fromkeys(out))


def linearization(model: Model, posture, hold=()):
    """``jflex.linearize`` at a posture (q or x0), with ``hold`` resolved (see :func:`resolve_hold`)."""
    x0 = expand_posture(model, posture)
    return x0, linearize(model, x0, hold=resolve_hold(model, hold))


def _effect_output(model: Model, name: str):
    """``x -> value`` of an effect output such as ``"beam.tip_position"`` at rest (zero rates and
    internal states), or None: the output resolution of :func:`jflex.simulate`."""
    fn = effect_output(model, name)
    if fn is None:
        return None
    lay = model.layout
    zx, zz = jnp.zeros(lay.nx), jnp.zeros(lay.nz)
    return lambda x: fn(x, zx, zz)


def tool_jacobian(model: Model, x0, keep, frame, reference: str, components: str):
    """Jacobian (3 or 6, len(keep)) of ``frame`` with respect to the kept coordinates.

    A rigid frame moves with the robot joint coordinates only (other kept coordinates get zero
    columns: an effect's coordinates, e.g. a beam's modes, do not carry the robot's frames). An
    effect output naming a point, e.g. ``"beam.tip_position"`` (world position of a flexible
    link's tip), is differentiated with respect to every coordinate, so its FRF includes the
    link's deflection; it has a translational Jacobian in world axes only.
    """
    if components not in ("linear", "angular", "full"):
        raise ShapeError(f"components must be 'linear', 'angular' or 'full', got '{components}'")
    r = model.rigid
    n = r.nq
    if isinstance(frame, str) and frame not in r.link_names and frame not in r.frame_names \
            and frame not in r.joint_names:
        out = _effect_output(model, frame)
        if out is not None:
            if components != "linear" or reference != "local_world_aligned":
                raise ShapeError(
                    f"frame '{frame}' is an effect output (a point): only components='linear' with "
                    f"reference='local_world_aligned' apply, got components='{components}', reference='{reference}'")
            J = jnp.atleast_2d(jax.jacfwd(out)(x0))
            return J[:, jnp.array(keep, dtype=int)]
    J = jacobian(r, x0[:n], frame, reference)
    J = {"linear": J[:3], "angular": J[3:], "full": J}[components]
    cols = [J[:, i] if i < n else jnp.zeros(J.shape[0], J.dtype) for i in keep]
    return jnp.stack(cols, axis=1)


def check_frequencies(omega, name="omega"):
    """A 1-D, finite, non-negative, strictly increasing grid [rad/s] (checked before tracing when
    concrete, through ``eqx.error_if`` when traced)."""
    w = jnp.asarray(omega, dtype=float)
    if w.ndim != 1 or w.shape[0] == 0:
        raise ShapeError(f"{name}: expected a 1-D frequency grid [rad/s], got shape {w.shape}")
    try:
        wn = np.asarray(w)
    except Exception:
        wn = None
    if wn is not None:
        if not np.all(np.isfinite(wn)):
            raise ParameterError(f"{name}: frequency grid contains NaN or inf")
        if wn.min() < 0:
            raise ParameterError(f"{name}: frequencies must be >= 0 [rad/s], got minimum {wn.min()}")
        if wn.shape[0] > 1 and not np.all(np.diff(wn) > 0):
            k = int(np.flatnonzero(~(np.diff(wn) > 0))[0])
            raise ParameterError(
                f"{name}: frequency grid must be strictly increasing; {name}[{k + 1}] = {wn[k + 1]} follows {wn[k]}"
            )
        return w
    bad = (w.min() < 0) | jnp.any(jnp.diff(w) <= 0) | ~jnp.all(jnp.isfinite(w))
    return eqx.error_if(w, bad, f"{name}: frequency grid must be finite, >= 0 and strictly increasing")
