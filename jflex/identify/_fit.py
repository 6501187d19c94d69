"""Output-error and mixed fits with optimistix: which leaves of a :class:`jflex.Model` are free
(:class:`Free`, :class:`ParameterSpec`), what they are compared with (data residuals in
``_residuals.py``) and :func:`fit`, which drives any optimistix least-squares solver or minimiser
step by step (progress, best-so-far kept on interrupt) and reports NRMSE per channel, the
Gauss-Newton covariance and the singular values of the residual Jacobian.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._errors import ParameterError, ShapeError
from .._progress import bar, note


# --- transforms: unconstrained u -> physical p ------------------------------------------------
class AbstractTransform(eqx.Module):
    """Map between an unconstrained optimisation variable ``u`` and a physical value ``p``."""

    def forward(self, u):
        raise NotImplementedError

    def inverse(self, p):
        raise NotImplementedError


class Identity(AbstractTransform):
    """``p = scale * u``: unconstrained, scaled so that ``u`` is of order one."""

    scale: jnp.ndarray

    def __init__(self, scale=1.0):
        self.scale = jnp.asarray(scale, dtype=float)

    def forward(self, u):
        return self.scale * u

    def inverse(self, p):
        return p / self.scale


class Log(AbstractTransform):
    """``p = exp(u)``: strictly positive, relative steps (stiffness, damping, masses)."""

    def forward(self, u):
        return jnp.exp(u)

    def inverse(self, p):
        p = jnp.asarray(p)
        return jnp.log(p)


class Bounded(AbstractTransform):
    """``p = lower + (upper - lower) sigmoid(u)``: strictly inside ``(lower, upper)`` (e.g. a
    fractional order in (0, 1))."""

    lower: jnp.ndarray
    upper: jnp.ndarray

    def __init__(self, lower, upper):
        self.lower = jnp.asarray(lower, dtype=float)
        self.upper = jnp.asarray(upper, dtype=float)

    def forward(self, u):
        return self.lower + (self.upper - self.lower) * jax.nn.sigmoid(u)

    def inverse(self, p):
        s = (jnp.asarray(p) - self.lower) / (self.upper - self.lower)
        return jnp.log(s) - jnp.log1p(-s)


class Free(eqx.Module):
    """One free leaf (or part of one) of a model.

    **Arguments:**

    - ``name``: label used in reports, e.g. ``"K"``.
    - ``where``: ``model -> array leaf``, as for ``eqx.tree_at`` (e.g.
      ``lambda m: m.effects[0].stiffness``).
    - ``index``: optional NumPy index into that leaf (``(0,)``, ``np.s_[1:3]``); default: all of it.
    - ``transform``: :class:`Log` (positive), :class:`Bounded`, :class:`Identity` (default, scaled
      by the start value's magnitude).
    - ``prior``: optional ``(mean, std)`` in physical units, added as residuals ``(p - mean)/std``.
    - ``on``: ``"model"`` (default) or ``"data"``: then ``where`` receives the tuple of data
      objects of the fit, e.g. ``lambda d: d[0].x0`` for an unknown initial state.
    """

    name: str = eqx.field(static=True)
    where: Callable = eqx.field(static=True)
    index: Any = eqx.field(static=True, default=None)
    transform: AbstractTransform | None = None
    prior: tuple | None = None
    on: str = eqx.field(static=True, default="model")

    def __check_init__(self):
        if self.on not in ("model", "data"):
            raise ParameterError(f"Free '{self.name}': on must be 'model' or 'data', got '{self.on}'")

    def _where(self, pair):
        return self.where(pair[0] if self.on == "model" else pair[1])

    def get(self, target):
        leaf = jnp.asarray(self._where(_pair(target)))
        return leaf if self.index is None else leaf[self.index]

    def set(self, target, value):
        def repl(leaf):
            leaf = jnp.asarray(leaf)
            if self.index is None:
                return jnp.broadcast_to(value, leaf.shape).astype(leaf.dtype)
            return leaf.at[self.index].set(value)

        pair = eqx.tree_at(self._where, _pair(target), replace_fn=repl)
        return pair if _is_pair(target) else pair[0]


def _is_pair(obj):
    return isinstance(obj, tuple) and len(obj) == 2 and isinstance(obj[1], tuple)


def _pair(obj):
    """``(model, data_tuple)`` from a model or a pair."""
    return obj if _is_pair(obj) else (obj, ())


class ParameterSpec(eqx.Module):
    """The free parameters of a fit: an ordered tuple of :class:`Free`, with their transforms
    resolved against a start model (``spec = ParameterSpec(frees).bind(model)``)."""

    frees: tuple[Free, ...]
    shapes: tuple = eqx.field(static=True, default=())

    def __init__(self, frees: Sequence[Free], shapes=()):
        self.frees = tuple(frees)
        self.shapes = tuple(shapes)
        names = [f.name for f in self.frees]
        if len(set(names)) != len(names):
            raise ParameterError(f"ParameterSpec: free parameter names must be unique, got {names}")

    def bind(self, model) -> "ParameterSpec":  # model: a Model or a (model, data tuple) pair
        """Fix shapes and default transforms from the start ``model``; checks start values."""
        frees, shapes = [], []
        for f in self.frees:
            try:
                v = np.asarray(f.get(model), dtype=float)
            except Exception as exc:
                raise ParameterError(f"ParameterSpec: free parameter '{f.name}': cannot read it from the model ({exc})") from None
            tr = f.transform
            if tr is None:
                tr = Identity(np.where(np.abs(v) > 0, np.abs(v), 1.0))
            u = np.asarray(tr.inverse(jnp.asarray(v)))
            if not np.isfinite(u).all():
                raise ParameterError(
                    f"ParameterSpec: start value of '{f.name}' = {v.tolist()} is outside its transform "
                    f"{type(tr).__name__} (Log needs > 0, Bounded needs lower < p < upper)"
                )
            frees.append(eqx.tree_at(lambda g: g.transform, f, tr, is_leaf=lambda x: x is None))
            shapes.append(v.shape)
        return ParameterSpec(frees, shapes)

    @property
    def size(self) -> int:
        return int(sum(int(np.prod(s)) for s in self.shapes))

    def labels(self) -> tuple[str, ...]:
        out = []
        for f, s in zip(self.frees, self.shapes):
            k = int(np.prod(s))
            out += [f.name] if s == () else [f"{f.name}[{i}]" for i in range(k)]
        return tuple(out)

    def _split(self, vec):
        out, k = [], 0
        for s in self.shapes:
            m = int(np.prod(s))
            out.append(vec[k : k + m].reshape(s))
            k += m
        return out

    def pack(self, model):
        """Unconstrained vector u (size,) of the model's current values."""
        return jnp.concatenate([jnp.ravel(f.transform.inverse(f.get(model))) for f in self.frees])

    def physical(self, u):
        """Physical values as one flat vector (size,)."""
        return jnp.concatenate([jnp.ravel(f.transform.forward(x)) for f, x in zip(self.frees, self._split(u))])

    def apply(self, model, u, *, physical: bool = False):
        """The model with the free leaves set from ``u`` (or from physical values)."""
        for f, x in zip(self.frees, self._split(u)):
            model = f.set(model, x if physical else f.transform.forward(x))
        return model

    def values(self, u) -> dict:
        """dict name -> physical value."""
        return {f.name: np.asarray(f.transform.forward(x)) for f, x in zip(self.frees, self._split(u))}

    def prior_residuals(self, u):
        parts = []
        for f, x in zip(self.frees, self._split(u)):
            if f.prior is not None:
                mean, std = f.prior
                parts.append(jnp.ravel((f.transform.forward(x) - jnp.asarray(mean)) / jnp.asarray(std)))
        return jnp.concatenate(parts) if parts else jnp.zeros(0)


# --- residuals --------------------------------------------------------------------------------
class AbstractData(eqx.Module):
    """Measured data of one kind and how the model predicts it.

    ``residuals(model)`` returns a dict channel -> real residual vector, already weighted and
    normalised so that its sum of squares is ``weight^2 * NRMSE^2`` of that channel (channels
    of different units weigh alike); ``nrmse(model)`` returns dict channel -> NRMSE [-].
    """

    def residuals(self, model) -> dict:
        raise NotImplementedError

    def nrmse(self, model) -> dict:
        raise NotImplementedError

    def nrmse_from_residuals(self, residuals: dict) -> dict | None:
        """NRMSE per channel from this object's ``residuals`` dict when it follows from them
        (saves :func:`fit` a separate compile of the model prediction); ``None`` otherwise."""
        return None


# --- the fit ------------------------------------------------------------------------------------
@dataclasses.dataclass
class FitResult:
    """Outcome of :func:`fit`.

    - ``model``: the fitted model (best parameters seen); ``data``: the data objects with any
      fitted data-side parameters (initial states).
    - ``values``, ``std``: dict name -> physical value and its standard deviation.
    - ``labels`` (static): one label per scalar parameter; ``covariance`` (p, p) Gauss-Newton
      ``s^2 (J^T J)^+`` in physical units, ``s^2 = |r|^2 / (m - p)`` (NaN when m <= p: exactly determined).
    - ``singular_values`` (p,): of the residual Jacobian w.r.t. the optimisation variables
      (``d r / d u``: relative changes for :class:`Log`, start-magnitude units for
      :class:`Identity`), largest first; ``weak_directions``: for singular values below
      ``1e-6`` of the largest (not identifiable from this data), the parameter combinations.
    - ``nrmse``: dict channel -> NRMSE; ``cost`` ``0.5 |r|^2``; ``history`` of costs;
      ``steps``; ``result``: solver message; ``interrupted``; ``seconds``; ``timing``: dict with
      ``compile_s`` (first residual-and-Jacobian evaluation, mostly compilation), ``jacobian_evals``
      and ``jacobian_run_s`` (their total run time after the first); with ``multistart`` also
      ``multistart_s`` (the vmapped candidate evaluation, compile included) and
      ``multistart_candidates``.
    - ``multistart``: with :class:`MultiStart`, one dict per local fit (candidate index, start
      values and cost, final values and cost, steps, result); ``history``, ``steps`` and
      ``result`` are those of the best one. Empty without.
    """

    model: Any
    data: tuple
    u: jnp.ndarray
    values: dict
    std: dict
    covariance: np.ndarray
    singular_values: np.ndarray
    nrmse: dict
    cost: float
    history: list
    steps: int
    seconds: float
    labels: tuple
    weak_directions: list
    result: str
    interrupted: bool
    timing: dict = dataclasses.field(default_factory=dict)
    multistart: list = dataclasses.field(default_factory=list)

    def summary(self) -> str:
        lines = [f"fit: {self.steps} steps, cost {self.cost:.6g}, {self.result}" + (" (interrupted)" if self.interrupted else "")]
        for k, v in self.values.items():
            s = self.std[k]
            lines.append(f"  {k} = {np.array2string(np.asarray(v), precision=6)} +/- {np.array2string(np.asarray(s), precision=3)}")
        lines.append("  NRMSE: " + ", ".join(f"{k} {v:.4g}" for k, v in self.nrmse.items()))
        lines.append("  singular values (d r / d u): " + np.array2string(self.singular_values, precision=3))
        for w in self.weak_directions:
            lines.append(f"  not identifiable: {w}")
        for r in self.multistart:
            lines.append(f"  multistart: candidate {r['candidate']}: cost {r['start_cost']:.4g} -> {r['cost']:.4g} in {r['steps']} steps ({r['result']})")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """JSON-friendly report (values, std, NRMSE, singular values, weak directions)."""
        return {
            "values": {k: np.asarray(v).tolist() for k, v in self.values.items()},
            "std": {k: np.asarray(v).tolist() for k, v in self.std.items()},
            "nrmse": dict(self.nrmse),
            "singular_values": np.asarray(self.singular_values).tolist(),
            "weak_directions": self.weak_directions,
            "cost": self.cost,
            "steps": self.steps,
            "seconds": self.seconds,
            "result": self.result,
            "interrupted": self.interrupted,
            "timing": dict(self.timing),
            **({"multistart": self.multistart} if self.multistart else {}),
        }


def _as_list(data):
    if isinstance(data, AbstractData):
        return [data]
    return list(data)


def residual_vector(model, data) -> jnp.ndarray:
    """All weighted residuals of ``data`` (one or a sequence of :class:`AbstractData`) as one vector."""
    parts = []
    for d in _as_list(data):
        parts += [jnp.ravel(v) for v in d.residuals(model).values()]
    return jnp.concatenate(parts)


def _linear_model(u, args):
    """The residual's first-order model about the evaluation point: ``r0 + J (u - u0)``.

    Gauss-Newton-type optimistix solvers evaluate ``fn`` only at ``state.y_eval`` and use its
    Jacobian there; handing them this linear model with ``(r0, J, u0)`` computed outside their
    ``step`` keeps the expensive model solve out of the step's program (see :func:`fit`)."""
    r0, J, u0 = args
    return r0 + J @ (u - u0), None


@eqx.filter_jit
def _gn_init(solver, u, r0, tags):
    f_struct = jax.ShapeDtypeStruct(r0.shape, r0.dtype)
    return solver.init(_linear_model, u, (r0, jnp.zeros((r0.shape[0], u.shape[0])), u), {}, f_struct, None, tags)


@eqx.filter_jit
def _gn_step(solver, u, state, args, tags):
    u2, state2, _ = solver.step(_linear_model, u, args, {}, state, tags)
    done, res = solver.terminate(_linear_model, u2, args, {}, state2, tags)
    # the residual at the accepted point u2 is the one the solver keeps (no new evaluation)
    return u2, state2, done, res, 0.5 * jnp.sum(state2.f_info.residual**2), state2.y_eval


def levenberg_marquardt(rtol: float = 1e-8, atol: float = 1e-8, *, expand_above: float = 0.75, **kw) -> optx.LevenbergMarquardt:
    """``optx.LevenbergMarquardt`` whose trust region grows (damping falls, x 1/3.5) whenever the
    actual cost reduction is at least ``expand_above`` of the predicted one.

    optimistix grows it only above 0.99 by default: once a few early steps of a strongly
    nonlinear fit (a time record whose frequency is off, so the residual's phase is) have shrunk
    it, steps on which the Gauss-Newton model is merely good (ratio 0.8-0.98) leave it small and
    the fit creeps along in the steepest-descent regime (a tip free vibration started +/-50 % off:
    over 60 iterations with the default, 23-31 with 0.75; the classical Moré choice).
    ``kw``: passed to ``optx.LevenbergMarquardt`` (norm, linear_solver, verbose)."""
    if not 0.0 < float(expand_above) < 1.0:
        raise ParameterError(f"levenberg_marquardt: expand_above must lie in (0, 1), got {expand_above}")
    lm = optx.LevenbergMarquardt(rtol=rtol, atol=atol, **kw)
    return eqx.tree_at(lambda s: s.search, lm, optx.ClassicalTrustRegion(high_cutoff=float(expand_above)))


@dataclasses.dataclass(frozen=True)
class MultiStart:
    """A cheap global stage for :func:`fit` (``multistart=MultiStart(...)``; off by default).

    ``n`` candidate starts are drawn by Latin-hypercube sampling inside ``bounds``, their costs
    ``0.5 |r|^2`` are evaluated in one vmapped call together with the given start, and the local
    solver is run from the ``keep`` cheapest; the fit with the lowest final cost is returned.

    **Arguments:**

    - ``n``: number of sampled candidates (>= 1).
    - ``keep``: number of local fits, from the cheapest candidates (the given start included).
    - ``bounds``: dict name -> ``(lower, upper)`` in physical units (scalars or arrays of the
      parameter's shape). Default per parameter: a :class:`Bounded` transform's own bounds; for
      :class:`Log` ``[p0 / span, p0 * span]`` (sampled log-uniformly); for :class:`Identity`
      ``p0 +/- (span - 1) * scale``.
    - ``span``: see ``bounds`` (> 1).
    - ``seed``: of the sampling.
    """

    n: int = 16
    keep: int = 3
    bounds: dict | None = None
    span: float = 3.0
    seed: int = 0

    def __post_init__(self):
        if int(self.n) < 1:
            raise ParameterError(f"MultiStart.n must be >= 1, got {self.n}")
        if int(self.keep) < 1:
            raise ParameterError(f"MultiStart.keep must be >= 1, got {self.keep}")
        if not float(self.span) > 1.0:
            raise ParameterError(f"MultiStart.span must be > 1, got {self.span}")

    def candidates(self, spec: "ParameterSpec", u0) -> np.ndarray:
        """``(n, size)`` unconstrained starts for the bound ``spec`` about ``u0``."""
        bounds = dict(self.bounds or {})
        unknown = set(bounds) - {f.name for f in spec.frees}
        if unknown:
            raise ParameterError(f"MultiStart.bounds: no free parameter named {sorted(unknown)}; "
                                 f"the fit has {[f.name for f in spec.frees]}")
        rng = np.random.default_rng(self.seed)
        n = int(self.n)
        cols = []
        for f, s, x in zip(spec.frees, spec.shapes, spec._split(jnp.asarray(u0))):
            tr = f.transform
            p0 = np.asarray(tr.forward(x), dtype=float)
            log = isinstance(tr, Log)
            if f.name in bounds:
                try:
                    lo, hi = (np.broadcast_to(np.asarray(b, dtype=float), s) for b in bounds[f.name])
                except Exception:
                    raise ParameterError(f"MultiStart.bounds['{f.name}'] must be (lower, upper), each a scalar or of "
                                         f"shape {s}, got {bounds[f.name]!r}") from None
            elif isinstance(tr, Bounded):
                lo, hi = (np.broadcast_to(np.asarray(b, dtype=float), s) for b in (tr.lower, tr.upper))
            elif log:
                lo, hi = p0 / self.span, p0 * self.span
            else:
                half = (self.span - 1.0) * np.broadcast_to(np.asarray(getattr(tr, "scale", 1.0), dtype=float), s)
                lo, hi = p0 - half, p0 + half
            if not np.all(lo < hi) or (log and not np.all(lo > 0)):
                raise ParameterError(f"MultiStart.bounds['{f.name}'] = ({lo.tolist()}, {hi.tolist()}): need lower < upper"
                                     + (" and lower > 0 (Log transform)" if log else ""))
            for j in range(int(np.prod(s))):
                # Latin hypercube: one draw per stratum, strata shuffled per coordinate; strictly
                # inside (0, 1) so that a Bounded transform's own bounds stay finite in u.
                t = np.clip((rng.permutation(n) + rng.uniform(size=n)) / n, 1e-6, 1 - 1e-6)
                a, b = np.ravel(lo)[j], np.ravel(hi)[j]
                cols.append(a * (b / a) ** t if log else a + t * (b - a))
        P = np.stack(cols, axis=1)  # physical, (n, size)
        return np.stack([_inverse(spec, p) for p in P])


def _inverse(spec, p):
    """Unconstrained u of a flat physical vector ``p``."""
    return np.concatenate([np.ravel(np.asarray(f.transform.inverse(x))) for f, x in zip(spec.frees, spec._split(jnp.asarray(p)))])


def _as_multistart(multistart):
    if multistart is None or multistart is False or (isinstance(multistart, int) and not isinstance(multistart, bool) and multistart == 0):
        return None
    if multistart is True:
        return MultiStart()
    if isinstance(multistart, int):
        return MultiStart(n=multistart)
    if isinstance(multistart, MultiStart):
        return multistart
    raise ParameterError(f"fit: multistart must be None, an int (number of candidates) or a MultiStart, got {multistart!r}")


# A step counts as no decrease below this relative change of the best cost.
_STALL_RTOL = 1e-10


@dataclasses.dataclass
class _Run:
    """One local solve: the best point seen and what is kept with it."""

    u: Any
    cost: float
    keep: Any
    history: list
    steps: int
    message: str
    interrupted: bool


def _loop(step, state, u0, cost0, keep0, max_steps, every, callback, spec, tag="", stall=None):
    """The step loop of every solver path: ``step(u, state) -> (u, state, done, result, cost,
    keep)``; ``keep`` (the Gauss-Newton path's residual and Jacobian at an accepted point, else
    ``None``) is stored with the best point. Ctrl-C ends it with the best point kept."""
    best = _Run(u0, cost0, keep0, [cost0], 0, "max_steps reached", False)
    u, flat = u0, 0
    shown_bar = bar(max_steps, f"fit{tag}", bool(every), unit="step")
    try:
        for k in range(1, max_steps + 1):
            best.steps = k
            u, state, done, res, cost, keep = step(u, state)
            cost = float(cost)
            best.history.append(cost)
            flat = 0 if np.isfinite(cost) and cost < best.cost * (1 - _STALL_RTOL) else flat + 1
            if np.isfinite(cost) and cost < best.cost:
                best.u, best.cost, best.keep = u, cost, keep
            if stall is not None and flat >= stall and not bool(done):
                done, res = True, None
            shown_bar.update(1)
            if every and (k % every == 0 or bool(done)):
                shown_bar.set_postfix_str(f"cost {cost:.6e}, best {best.cost:.6e}")
            if callback is not None:
                callback(k, best.cost, spec.values(best.u))
            if bool(done):
                best.message = (f"stalled (no cost decrease in {stall} steps)" if res is None
                                else "converged" if res == optx.RESULTS.successful else str(res))
                break
    except KeyboardInterrupt:
        best.interrupted, best.message = True, "interrupted"
    finally:
        shown_bar.close()
    return best


def fit(
    model,
    spec: ParameterSpec,
    data,
    solver=None,
    *,
    max_steps: int = 100,
    progress: bool | int = True,
    callback: Callable | None = None,
    weak_tol: float = 1e-6,
    multistart: "MultiStart | int | None" = None,
    stall: int | None = None,
    jacobian: str = "dense",
) -> FitResult:
    """Fit the free parameters ``spec`` of ``model`` to ``data`` with an optimistix solver.

    **Arguments:**

    - ``model``: the start :class:`jflex.Model` (also supplies every fixed parameter).
    - ``spec``: :class:`ParameterSpec` (bound here to ``model``).
    - ``data``: one :class:`AbstractData` or a sequence (e.g. torque + modal + FRF): one weighted fit.
    - ``solver``: an optimistix least-squares solver (default ``LevenbergMarquardt(rtol=1e-8,
      atol=1e-8)``; for time records :func:`levenberg_marquardt` converges in far fewer
      iterations from a distant start) or minimiser (``optx.BFGS``; the cost is then ``0.5 |r|^2``). Jacobians are
      exact (forward/reverse-mode AD), never finite differences.
    - ``max_steps`` (per local solve); ``progress``: a tqdm bar of the steps on stderr with the
      cost (refreshed every ``progress`` steps when an int; off a terminal, plain lines at most every 5 s;
      ``False``: none); ``callback(step, cost, best_values)`` after each step (e.g. to checkpoint).
    - ``multistart``: ``None`` (default: one local solve from ``model``), a :class:`MultiStart`,
      or an int ``n`` (``MultiStart(n)``): sampled starts ranked by cost in one vmapped
      evaluation, local solves from the best few, the lowest final cost returned. For costs with
      local minima (e.g. an amplitude-dependent frequency in a time record).
    - ``stall``: ``None`` (default) or a number of steps: stop a local solve (result
      ``"stalled ..."``) once that many consecutive steps have not lowered the cost. At the
      minimum of a residual from an adaptive ODE solve, whose error makes it rough at the solve's
      tolerance, the solver keeps rejecting steps and its Cauchy test (on an accepted step) may
      not fire before ``max_steps``.
    - ``jacobian``: ``"dense"`` (default: ``jax.jacfwd`` through the models, any data) or
      ``"sparse"``: every :class:`FRFData` residual gets the structured exact Jacobian of
      :func:`sparse_frf_residual` (the entries of ``(M, C, K)`` each parameter moves, found once
      at the start; 2.5-4x the residual instead of 7-12x), the other data the dense one. Raises
      if no data is an FRFData, or for an FRFData whose tool Jacobian depends on the parameters,
      whose model has a frequency-dependent effect (hysteretic) or whose own arrays are free.

    Gauss-Newton-type solvers (Levenberg-Marquardt, Gauss-Newton, Dogleg) get the residual and
    its Jacobian from ONE compiled function of the parameters (``jax.jacfwd``: the p tangents
    ride along the primal in one batched solve, the parameters are traced arguments, so no
    recompilation across steps or starts) that is evaluated outside the solver's step; the same
    values serve the start check, every step and the final report. (Letting the solver
    ``jax.linearize`` a time simulation instead re-runs the whole ODE loop for every Jacobian
    column batch and compiles the solve three times into each step.)

    Ctrl-C stops the loop: the best parameters seen are kept and ``interrupted`` is set.

    **Returns:** :class:`FitResult`.
    """
    data = tuple(_as_list(data))
    pair = (model, data)
    spec = spec.bind(pair)
    solver = solver if solver is not None else optx.LevenbergMarquardt(rtol=1e-8, atol=1e-8)
    ms = _as_multistart(multistart)
    if stall is not None and int(stall) < 1:
        raise ParameterError(f"fit: stall must be None or a number of steps >= 1, got {stall}")
    # strongly typed: a start packed from Python floats is weakly typed, and the solver's first
    # iterate (strong) would compile the residual and Jacobian a second time
    u0 = jnp.asarray(spec.pack(pair), dtype=jnp.result_type(float))
    if jacobian not in ("dense", "sparse"):
        raise ParameterError(f"fit: jacobian must be 'dense' or 'sparse', got {jacobian!r}")
    sparse = {}
    if jacobian == "sparse":
        from ._frf_jacobian import sparse_parts

        sparse = sparse_parts(spec, pair, u0)

    def resid_parts(u):
        m, d = spec.apply(pair, u)
        parts = [sparse[i].parts(u) if i in sparse else dict(di.residuals(m)) for i, di in enumerate(d)]
        r = jnp.concatenate([jnp.ravel(v) for p in parts for v in p.values()] + [spec.prior_residuals(u)])
        return r, parts

    def resid(u, args):
        return resid_parts(u)[0]

    def cost_of(u):
        return 0.5 * jnp.sum(resid(u, None) ** 2)

    is_min = isinstance(solver, optx.AbstractMinimiser)
    every = int(progress) if progress and not isinstance(progress, bool) else (1 if progress else 0)
    timing = {}
    t_start = time.perf_counter()
    tags = frozenset()
    gauss_newton = not is_min and isinstance(solver, optx.AbstractGaussNewton)
    if gauss_newton:
        @eqx.filter_jit
        def r_and_jac(u):
            def g(v):
                r, parts = resid_parts(v)
                return r, (r, parts)

            J, (r, parts) = jax.jacfwd(g, has_aux=True)(u)
            return r, J, parts

        cache = {}

        def evaluate(u):
            key = np.asarray(u).tobytes()
            if key not in cache:
                t0 = time.perf_counter()
                out = jax.block_until_ready(r_and_jac(u))
                dt = time.perf_counter() - t0
                if "compile_s" not in timing:
                    timing.update(compile_s=dt, jacobian_evals=1, jacobian_run_s=0.0)
                else:
                    timing["jacobian_evals"] += 1
                    timing["jacobian_run_s"] += dt
                cache.clear()  # the solver needs the latest; the best one is kept apart
                cache[key] = out
            return cache[key]

        def start(u):
            ev = evaluate(u)
            return float(0.5 * jnp.sum(ev[0] ** 2)), ev, (_gn_init(solver, u, ev[0], tags), u)

        def step(u, st):
            state, y_ev = st
            ev = evaluate(y_ev)
            u2, state2, done, res, cost, y_next = _gn_step(solver, u, state, (ev[0], ev[1], y_ev), tags)
            # an accepted step moves to the point just evaluated: its Jacobian is the one to report
            keep = ev if np.array_equal(np.asarray(u2), np.asarray(y_ev)) else None
            return u2, (state2, y_next), done, res, cost, keep
    else:
        fn = (lambda u, a: (cost_of(u), None)) if is_min else (lambda u, a: (resid(u, a), None))
        f_struct, aux_struct = jax.eval_shape(lambda: fn(u0, None))
        init = eqx.filter_jit(lambda u: solver.init(fn, u, None, {}, f_struct, aux_struct, tags))
        cost_jit = eqx.filter_jit(cost_of)

        @eqx.filter_jit
        def _step(u, state):
            u2, state2, _ = solver.step(fn, u, None, {}, state, tags)
            done, res = solver.terminate(fn, u2, None, {}, state2, tags)
            return u2, state2, done, res, cost_of(u2)

        def start(u):
            return float(cost_jit(u)), None, init(u)

        def step(u, state):
            return (*_step(u, state), None)

    starts, ms_report = [u0], []
    if ms is not None:
        t0 = time.perf_counter()
        U = jnp.concatenate([u0[None], jnp.asarray(ms.candidates(spec, u0))])
        costs = np.asarray(eqx.filter_jit(jax.vmap(cost_of))(U))
        costs = np.where(np.isfinite(costs), costs, np.inf)
        order = [int(i) for i in np.argsort(costs, kind="stable") if np.isfinite(costs[i])][: int(ms.keep)]
        timing["multistart_s"] = time.perf_counter() - t0
        timing["multistart_candidates"] = int(U.shape[0])
        if not order:
            raise ParameterError("fit: the residual is not finite at any multistart candidate; check the start model, the data and MultiStart.bounds")
        starts = [U[i] for i in order]
        ms_report = [{"candidate": i, "start": {k: np.asarray(v).tolist() for k, v in spec.values(U[i]).items()},
                      "start_cost": float(costs[i])} for i in order]
        note(f"fit multistart: {U.shape[0]} candidates in {timing['multistart_s']:.1f} s, local fits from costs "
             + ", ".join(f"{costs[i]:.3e}" for i in order), bool(every))

    best = None
    for i, us in enumerate(starts):
        cost0, keep0, state = start(us)
        if not np.isfinite(cost0):
            raise ParameterError("fit: the residual is not finite at the start parameters; check the start model and the data")
        run = _loop(step, state, us, cost0, keep0, max_steps, every, callback, spec, f" [start {i}]" if ms is not None else "",
                    None if stall is None else int(stall))
        if ms_report:
            ms_report[i].update(cost=run.cost, steps=run.steps, result=run.message,
                                values={k: np.asarray(v).tolist() for k, v in spec.values(run.u).items()})
        if best is None or run.cost < best.cost:
            best = run
        if run.interrupted:
            best.interrupted, best.message = True, "interrupted"
            break
    seconds = time.perf_counter() - t_start
    if not gauss_newton:
        return _report(pair, spec, best.u, best.cost, best.history, best.steps, seconds, best.message, best.interrupted,
                       weak_tol, timing=timing, multistart=ms_report)
    if best.keep is None:
        best.keep = evaluate(best.u)
    timing["total_s"] = time.perf_counter() - t_start
    r, J_u, parts = best.keep
    nrmse = _nrmse_of(pair, spec, best.u, parts)
    n_data = r.shape[0] - spec.prior_residuals(best.u).shape[0]  # the prior rows are folded in by _report
    return _report(pair, spec, best.u, best.cost, best.history, best.steps, seconds, best.message, best.interrupted, weak_tol,
                   pre=(np.asarray(J_u)[:n_data], np.asarray(r)[:n_data], nrmse), timing=timing, multistart=ms_report)


def _nrmse_of(pair, spec, u, parts):
    """NRMSE per channel from the residuals where the data objects allow it, else predicted."""
    out, missing = {}, []
    for i, (d, p) in enumerate(zip(pair[1], parts)):
        v = d.nrmse_from_residuals(p)
        if v is None:
            missing.append(i)
        else:
            out.update({k: float(x) for k, x in v.items()})
    if missing:
        @eqx.filter_jit
        def f(uu):
            m, dd = spec.apply(pair, uu)
            o = {}
            for i in missing:
                o.update(dd[i].nrmse(m))
            return o

        out.update({k: float(v) for k, v in f(u).items()})
    return out


def _report(pair, spec, u, cost, history, steps, seconds, message, interrupted, weak_tol, pre=None, timing=None, multistart=()):
    """``pre``: ``(J_u, r, nrmse)`` already known at ``u`` (Jacobian w.r.t. the optimisation
    variables u, data residuals without the prior rows); otherwise computed here."""
    p = spec.physical(u)
    fitted, fitted_data = spec.apply(pair, u)

    def r_of_p(pp):
        m, d = spec.apply(pair, pp, physical=True)
        return residual_vector(m, d)

    @eqx.filter_jit
    def jac_and_nrmse(pp):
        m, dd = spec.apply(pair, pp, physical=True)
        out = {}
        for d in dd:
            out.update(d.nrmse(m))
        return jax.jacfwd(r_of_p)(pp), r_of_p(pp), out

    dpdu = np.asarray(jax.jacfwd(spec.physical)(u)).diagonal()  # the transforms act elementwise
    if pre is None:
        J, r, nrmse = jac_and_nrmse(p)
        J, r = np.asarray(J), np.asarray(r)
        nrmse = {k: float(v) for k, v in nrmse.items()}
    else:
        J_u, r, nrmse = pre
        J = np.asarray(J_u) / dpdu[None, :]
    m_, n_ = J.shape
    # With no more residuals than parameters the noise level cannot be estimated from the fit.
    s2 = float(r @ r) / (m_ - n_) if m_ > n_ else float("nan")
    # Parameters and the prior are folded into the information matrix so that a prior counts.
    info = J.T @ J
    pr = []
    for f, s in zip(spec.frees, spec.shapes):
        k = int(np.prod(s))
        pr += list(np.broadcast_to(np.asarray(f.prior[1], float), s).ravel() ** -2.0) if f.prior is not None else [0.0] * k
    info = info + np.diag(pr) * (s2 if np.isfinite(s2) else 1.0) if any(pr) else info
    cov = s2 * np.linalg.pinv(info)
    std_flat = np.sqrt(np.clip(np.diag(cov), 0, None))
    # Columns scaled by dp/du: the sensitivities to the optimisation variables, which are relative
    # for Log, bounded-relative for Bounded and in units of the start magnitude for Identity.
    scale = np.abs(dpdu)
    Js = J * scale
    _, sv, Vt = np.linalg.svd(Js, full_matrices=False)
    labels = spec.labels()
    weak = []
    for i, s in enumerate(sv):
        if s <= weak_tol * sv[0]:
            v = Vt[i]
            top = np.argsort(-np.abs(v))[:4]
            weak.append({"singular_value": float(s), "combination": {labels[j]: float(v[j]) for j in top if abs(v[j]) > 1e-3}})
            # pinv would report a zero variance along a direction the data cannot see at all
            std_flat = np.where(np.abs(v) > 1e-3, np.inf, std_flat)
    std_flat = np.asarray(std_flat, dtype=float)
    std = {f.name: x for f, x in zip(spec.frees, [a.reshape(s) for a, s in zip(np.split(std_flat, np.cumsum([int(np.prod(s)) for s in spec.shapes])[:-1]), spec.shapes)])}
    return FitResult(
        model=fitted, data=fitted_data, u=u, values=spec.values(u), std=std, covariance=cov, singular_values=sv, nrmse=nrmse,
        cost=float(cost), history=history, steps=int(steps), seconds=float(seconds), labels=labels,
        weak_directions=weak, result=message, interrupted=interrupted, timing=dict(timing or {}), multistart=list(multistart),
    )
