"""Time responses of a :class:`jflex.Model` with diffrax.

``simulate`` integrates ``M(x) xdd + h = B u(t) + sum f_e``, ``zd = g`` (see
:func:`jflex.model_forward_dynamics`) with an adaptive diffrax solver passed through as an
object, lands steps on the inputs' discontinuities, and returns the requested outputs at the
requested times. Everything is differentiable (gradients flow through the solve).
"""

from __future__ import annotations

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._dynamics import frame_placement, potential_energy
from ._errors import ShapeError, SolverError
from ._inputs import AbstractInput, Zero
from ._model import Model, _effect_potential, initial_state, input_matrix, mass_matrix, model_forward_dynamics


class Response(eqx.Module):
    """Result of :func:`simulate`.

    **Fields:** ``ts`` (T,) [s]; ``outputs``: dict name -> (T, ...) array; ``result``: the diffrax
    result code; ``num_steps``: accepted + rejected steps taken. ``response["name"]`` indexes outputs.
    """

    ts: jnp.ndarray
    outputs: dict
    result: diffrax.RESULTS
    num_steps: jnp.ndarray

    def __getitem__(self, name):
        return self.outputs[name]


def total_energy(model: Model, x, xd):
    """Mechanical energy ``T + V`` [J] of the model at one state (rigid + every effect)."""
    r = model.rigid
    n = r.nq
    T = 0.5 * xd @ mass_matrix(model, x) @ xd
    return T + potential_energy(r, x[:n]) + _effect_potential(model, x)


def nonconservative_force(model: Model, t, x, xd, z, u):
    """``B u + sum_e f_e`` (nx,): the forces whose power changes the mechanical energy."""
    r, lay = model.rigid, model.layout
    f = input_matrix(model) @ u
    for e, s in zip(model.effects, lay.slots):
        f = f + e.generalized_force(r, s, t, x, xd, z)
    return f


def _vf_plain(t, y, args):
    model, inputs = args
    x, xd, z, _ = y
    xdd, zd = model_forward_dynamics(model, t, x, xd, z, inputs(t))
    return xd, xdd, zd, jnp.zeros(())


def _vf_work(t, y, args):
    model, inputs = args
    x, xd, z, _ = y
    u = inputs(t)
    xdd, zd = model_forward_dynamics(model, t, x, xd, z, u)
    return xd, xdd, zd, xd @ nonconservative_force(model, t, x, xd, z, u)


@eqx.filter_jit
def _check_rate(model, inputs, t, y):
    rate = _vf_plain(t, y, (model, inputs))
    return jnp.all(jnp.array([jnp.all(jnp.isfinite(a)) for a in jax.tree_util.tree_leaves((y, rate))]))


@eqx.filter_jit
def _compute_outputs(model, names, inputs, ts, xs, xds, zs):
    us = jax.vmap(inputs)(ts)
    return {name: jax.vmap(_resolve_output(model, name))(ts, xs, xds, zs, us) for name in names}


def effect_output(model: Model, name: str):
    """``(x, xd, z) -> value`` of the first effect providing the output ``name`` (e.g.
    ``"beam.tip_position"``), or None. Effects answer ``None`` for names they do not know, so a
    probe at the zero state resolves the name once, outside any trace."""
    r, lay = model.rigid, model.layout
    for e, s in zip(model.effects, lay.slots):
        if e.output(r, s, name, jnp.zeros(lay.nx), jnp.zeros(lay.nx), jnp.zeros(lay.nz)) is not None:
            return lambda x, xd, z, e=e, s=s: e.output(r, s, name, x, xd, z)
    return None


def _resolve_output(model: Model, name: str):
    """A function ``(t, x, xd, z, u) -> value`` for one output name (static resolution)."""
    r, lay = model.rigid, model.layout
    n = r.nq
    simple = {
        "x": lambda t, x, xd, z, u: x,
        "xd": lambda t, x, xd, z, u: xd,
        "z": lambda t, x, xd, z, u: z,
        "q": lambda t, x, xd, z, u: x[:n],
        "qd": lambda t, x, xd, z, u: xd[:n],
        "u": lambda t, x, xd, z, u: u,
        "energy": lambda t, x, xd, z, u: total_energy(model, x, xd),
        "power": lambda t, x, xd, z, u: xd @ nonconservative_force(model, t, x, xd, z, u),
    }
    if name in simple:
        return simple[name]
    if name in lay.coord_names:
        i = lay.coord_names.index(name)
        return lambda t, x, xd, z, u: x[i]
    if name.endswith("_d") and name[:-2] in lay.coord_names:
        i = lay.coord_names.index(name[:-2])
        return lambda t, x, xd, z, u: xd[i]
    if name in lay.state_names:
        i = lay.state_names.index(name)
        return lambda t, x, xd, z, u: z[i]
    if name.startswith("frame:"):
        fr = name[len("frame:"):]
        r.frame_index(fr)  # raises a named error for an unknown frame
        return lambda t, x, xd, z, u: frame_placement(r, x[:n], fr)[:3, 3]
    fn = effect_output(model, name)
    if fn is not None:
        return lambda t, x, xd, z, u: fn(x, xd, z)
    known = list(simple) + ["work"] + list(lay.coord_names) + [c + "_d" for c in lay.coord_names]
    known += list(lay.state_names) + ["frame:<name>", "<effect>.<output> (e.g. beam.tip_deflection, beam.strain@0.3)"]
    raise ShapeError(f"simulate: unknown output '{name}'; known outputs: {known}")


_ADVICE = {
    "max_steps": "increase max_steps, loosen rtol/atol, or, if the system is stiff (high stiffness, "
    "Kelvin-Voigt or fractional filter poles, hysteresis reversal rate), use a stiff solver such as "
    "diffrax.Kvaerno5()",
    "nonfinite": "the right-hand side produced NaN/inf: check the parameters (non-positive mass, "
    "singular mass matrix) and the initial state, or tighten the tolerances",
    "other": "see the diffrax message; try a smaller dt0, tighter tolerances or a stiff solver",
}


def _failure_message(result, finite: bool, max_steps) -> str | None:
    if result == diffrax.RESULTS.successful and finite:
        return None
    if result == diffrax.RESULTS.max_steps_reached:
        return f"simulate: the solver reached max_steps={max_steps} before the final time; " + _ADVICE["max_steps"]
    if not finite:
        return "simulate: the solution contains NaN or inf; " + _ADVICE["nonfinite"]
    return f"simulate: the solver failed ({result}); " + _ADVICE["other"]


def simulate(
    model: Model,
    ts,
    x0=None,
    xd0=None,
    z0=None,
    *,
    inputs: AbstractInput | None = None,
    outputs=("x",),
    solver=None,
    rtol: float = 1e-8,
    atol: float = 1e-10,
    dt0=None,
    max_steps: int = 100_000,
    jump_ts=(),
    t0=None,
    adjoint=None,
    throw: bool = True,
) -> Response:
    """Integrate a model from ``t0`` over the sample times ``ts`` and return named outputs.

    **Arguments:**

    - ``model``: :class:`jflex.Model`.
    - ``ts`` (T,) increasing sample times [s]; the solve runs from ``t0`` (default ``ts[0]``) to ``ts[-1]``.
    - ``x0``, ``xd0`` (nx,) initial coordinates and rates (default 0); ``z0`` (nz,) internal
      states (default :func:`jflex.initial_state`).
    - ``inputs``: an :class:`AbstractInput` giving ``u(t)`` (n,) (default zero); its
      :meth:`~AbstractInput.jump_times` and ``jump_ts`` are declared to the step controller.
    - ``outputs``: names: ``"x"``, ``"xd"``, ``"z"``, ``"q"``, ``"qd"``, ``"u"``, ``"energy"`` [J],
      ``"power"`` [W] (of inputs and non-conservative forces), ``"work"`` [J] (its time integral,
      integrated with the states), any coordinate name (and ``name + "_d"`` for its rate), any
      state name, ``"frame:<frame>"`` (position (3,) [m] of a rigid frame), and effect outputs such
      as ``"beam.tip_deflection"`` [m], ``"beam.tip_position"`` [m], ``"beam.strain@0.3"``.
    - ``solver``: a diffrax solver instance (default ``diffrax.Tsit5()``; ``diffrax.Dopri8()``,
      stiff ``diffrax.Kvaerno5()``).
    - ``rtol``, ``atol``, ``dt0``, ``max_steps``: step control (``dt0=None`` lets diffrax choose).
    - ``adjoint``: a diffrax adjoint (default ``RecursiveCheckpointAdjoint``).
    - ``throw``: raise :class:`jflex.SolverError` on failure (max steps, NaN); under ``jit``/``vmap``
      this becomes an ``eqx.error_if`` runtime error with the same message.

    **Returns:** :class:`Response` with ``outputs[name]`` of shape (T, ...).
    """
    lay = model.layout
    nx, nz, n = lay.nx, lay.nz, model.rigid.nq
    ts = jnp.asarray(ts, dtype=float)
    if ts.ndim != 1 or ts.shape[0] < 1:
        raise ShapeError(f"simulate: ts must be a non-empty 1-D array of times, got shape {ts.shape}")
    x0 = jnp.zeros(nx) if x0 is None else jnp.asarray(x0, dtype=float)
    xd0 = jnp.zeros(nx) if xd0 is None else jnp.asarray(xd0, dtype=float)
    z0 = initial_state(model) if z0 is None else jnp.asarray(z0, dtype=float)
    for name, a, m in (("x0", x0, nx), ("xd0", xd0, nx), ("z0", z0, nz)):
        if a.shape != (m,):
            what = lay.coord_names if name != "z0" else lay.state_names
            raise ShapeError(f"simulate: {name} must have shape ({m},) (entries {list(what)}), got {a.shape}")
    nu = input_matrix(model).shape[1]
    inputs = Zero(nu) if inputs is None else inputs
    u_probe = jax.eval_shape(inputs, 0.0)
    if u_probe.shape != (nu,):
        raise ShapeError(f"simulate: inputs(t) must have shape ({nu},) (one entry per actuator), got {u_probe.shape}")
    if isinstance(outputs, str):
        outputs = (outputs,)
    fns = {name: _resolve_output(model, name) for name in outputs if name != "work"}
    want_work = "work" in outputs
    solver = diffrax.Tsit5() if solver is None else solver
    adjoint = diffrax.RecursiveCheckpointAdjoint() if adjoint is None else adjoint
    t_start = ts[0] if t0 is None else jnp.asarray(t0, dtype=float)

    # Jumps must be concrete: they are known at model-build time, never traced.
    try:
        ta, tb = float(t_start), float(ts[-1])
        jumps = sorted(set(float(j) for j in tuple(inputs.jump_times()) + tuple(jump_ts) if ta < float(j) < tb))
    except (jax.errors.ConcretizationTypeError, TypeError):
        jumps = sorted(set(float(j) for j in tuple(inputs.jump_times()) + tuple(jump_ts)))

    # A NaN at the start would only show up as max_steps after the controller shrinks dt
    # forever: catch it here, by name.
    y0 = (x0, xd0, z0, jnp.zeros(()))
    if throw and not any(isinstance(a, jax.core.Tracer) for a in jax.tree_util.tree_leaves((model, inputs, t_start, y0))):
        rate = _check_rate(model, inputs, t_start, y0)
        if not bool(rate):
            raise SolverError(
                f"simulate: the right-hand side is NaN or inf at t0 = {float(t_start)} s; " + _ADVICE["nonfinite"]
            )

    # tolerances as arrays: a new tolerance then reuses the compiled solve
    controller = diffrax.PIDController(rtol=jnp.asarray(rtol, dtype=float), atol=jnp.asarray(atol, dtype=float))
    if jumps:
        controller = diffrax.ClipStepSizeController(controller, jump_ts=jnp.asarray(jumps))
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(_vf_work if want_work else _vf_plain),
        solver,
        t0=t_start,
        t1=ts[-1],
        dt0=dt0,
        y0=y0,
        args=(model, inputs),
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=controller,
        max_steps=max_steps,
        adjoint=adjoint,
        throw=False,
    )
    xs, xds, zs, ws = sol.ys
    finite = jnp.all(jnp.isfinite(xs)) & jnp.all(jnp.isfinite(xds))
    result = sol.result
    if throw:
        traced = isinstance(finite, jax.core.Tracer) or any(
            isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(result)
        )
        if traced:
            bad_steps = result == diffrax.RESULTS.max_steps_reached
            xs = eqx.error_if(xs, bad_steps, _failure_message(diffrax.RESULTS.max_steps_reached, True, max_steps))
            xs = eqx.error_if(xs, ~finite, _failure_message(diffrax.RESULTS.successful, False, max_steps))
            xs = eqx.error_if(xs, result != diffrax.RESULTS.successful, "simulate: the solver failed; " + _ADVICE["other"])
        else:
            msg = _failure_message(result, bool(finite), max_steps)
            if msg is not None:
                raise SolverError(msg)
    out = _compute_outputs(model, tuple(fns), inputs, ts, xs, xds, zs)
    if want_work:
        out["work"] = ws
    return Response(ts=ts, outputs=out, result=result, num_steps=sol.stats["num_steps"])
