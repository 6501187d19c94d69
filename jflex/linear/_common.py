"""Shared plumbing of the linear analyses: postures, held coordinates, tool Jacobians, checks."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import has_inertia
from .._dynamics import jacobian
from .._errors import ParameterError, ShapeError
from .._model import Model, linearize, resolve_hold as resolve_hold
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


def linearization(model: Model, posture, hold=()):
    """``(x0, jflex.linearize(model, x0, hold=hold))`` at a posture (q or x0); ``hold`` as in
    :func:`resolve_hold`."""
    x0 = expand_posture(model, posture)
    return x0, linearize(model, x0, hold=hold)


def check_inertia(fn: str, model: Model) -> None:
    """A model whose rigid robot has no inertial parameters at all (known at trace time) has no
    modes: say so before computing (a traced robot is checked through :func:`require_mass`)."""
    has_inertia(fn, model.rigid)


def mass_ok(M):
    """True where the (kept) mass matrix ``M`` is positive definite (its Cholesky factor is finite)."""
    return jnp.all(jnp.isfinite(jnp.linalg.cholesky(M)))


def require_mass(fn: str, ok, value):
    """``value`` once ``ok`` (from :func:`mass_ok`) holds: a :class:`ParameterError` at once when
    ``ok`` is concrete, an ``eqx.error_if`` on ``value`` when it is traced."""
    msg = (f"{fn}: the mass matrix over the kept coordinates is not positive definite: a free coordinate moves "
           "no inertia (e.g. a link with zero mass and inertia, or a motor coordinate of a flexible joint with "
           "zero rotor_inertia); give it inertia or hold it (hold=...)")
    if isinstance(ok, jax.core.Tracer):
        return eqx.error_if(value, ~ok, msg)
    if not bool(ok):
        raise ParameterError(msg)
    return value


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
