"""Batch evaluation of a per-item function over a large batch: chunked (bounded memory), sharded
across the devices (on CPU, one per process), with progress and per-chunk files so an interrupted sweep keeps what it
has already computed and resumes where it stopped.

Several hosts: start the same script on every host after
``jax.distributed.initialize(coordinator_address, num_processes, process_id)``; ``jax.devices()``
then lists every host's devices and the same ``sweep`` call shards each chunk across all of them
(give each process its own ``out_dir`` or let process 0 write, see the README).
"""

from __future__ import annotations

import functools
import json
import math
import os
import pathlib
import time
import types
import zipfile
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.experimental import multihost_utils
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from . import _checks
from ._allocator import tune_allocator
from ._errors import ConfigError, DataError, ParameterError, ShapeError
from ._fingerprint import fingerprint
from ._paths import output_folder
from ._program_cache import persistent_jit
from ._progress import bar
from ._trig import vectorised

_MANIFEST = "sweep.json"
_CHANGED = {
    "function_hash": "the function or a value it reaches changed (its code, closure, defaults or globals: e.g. a robot)",
    "inputs_hash": "the inputs changed",
}
_FP_KEY = "__fingerprint__"


def _tune_allocator_once():
    # batch outputs of a few MB per call otherwise page-fault afresh on many calls (see
    # jflex/_allocator.py); JFLEX_TUNE_ALLOCATOR=0 leaves glibc's defaults
    if os.environ.get("JFLEX_TUNE_ALLOCATOR", "1") != "0":
        tune_allocator()


_PROGRAMS = ("vmap", "blocks", "unfused", "barriers", "fastest")
# lax.map block size when none is given: a block of a rigid-body kernel's working set stays in a
# CPU core's cache at 1024 states; a GPU needs far more states in flight to fill its cores (an H100
# keeps 132 x 2048 threads resident), so blocks there hold 2**18 states (a rule, not a measurement)
_DEFAULT_BLOCK = {"cpu": 1024}
_DEFAULT_BLOCK_ACCELERATOR = 1 << 18


def default_batch_size(backend: str | None = None) -> int:
    """The ``lax.map`` block size :func:`batched` uses on ``backend`` (default: JAX's default
    backend) when ``batch_size`` is not given: 1024 states on CPU, 2**18 on GPU and TPU."""
    backend = backend or jax.default_backend()
    return _DEFAULT_BLOCK.get(backend, _DEFAULT_BLOCK_ACCELERATOR)


def batched(fn: Callable, *, program: str | None = None, batch_size: int | None = None, fuse: bool | None = None,
            devices=None):
    """A jitted batch version of a per-item ``fn`` over the leading axis of its arguments.

    ``program`` chooses how the batch is compiled:

    - ``"vmap"`` (the default): one fused ``jax.jit(jax.vmap(fn))``. On CPU, ``fn`` is traced
      with the kernels' cosines and sines of joint angles as plain arithmetic (``jflex/_trig.py``),
      which lets XLA:CPU vectorise the fused loops: on the 7-joint Panda at 1e5 states ``rnea``
      ran 0.34 us a state instead of 0.66, ``aba`` 0.69 instead of 1.05, ``crba`` 0.23 instead
      of 1.01, for 0.1-0.5 s more compilation.
    - ``"barriers"``: ``"vmap"`` compiled with the optimization barriers kept through XLA's
      fusion pass (XLA:CPU otherwise drops them first and recomputes each body's shared work in
      every fused consumer). The Panda's ``aba`` then ran 0.45 us a state, ``rnea`` 0.27, for
      0.6-0.9 s more compilation: worth it for many calls, not for one. A top-level call only
      (inside a caller's ``jit`` JAX takes no compiler options: it compiles as ``"vmap"``).
    - ``"blocks"``: ``lax.map`` over blocks of ``batch_size`` states (default
      :func:`default_batch_size`: 1024 on CPU, 2**18 on GPU), so the working set of a block stays
      in cache and memory is bounded by one block; faster than ``"vmap"`` for the long derivative
      kernels (``rnea_derivatives``, ``aba_derivatives``) on CPU.
    - ``"unfused"``: one vmapped program compiled without XLA's fusion pass (CPU only; elsewhere it
      is ``"vmap"``). Fastest for ``crba`` on CPU, but it compiles 5-8x longer, and XLA:CPU
      without fusion has returned wrong results for other programs (lax.map blocks, a modal
      linearisation's mass matrix on jax 0.10.2): use it only for ``rnea``, ``crba`` and ``aba``,
      which the tests check against Pinocchio.
    - ``"fastest"``: at the first call for each set of argument shapes and dtypes, compile every
      program above that applies to the backend, time each on that call's arguments and keep the
      fastest whose results equal ``"vmap"``'s (to 1e-9 relative); later calls with those shapes run
      it at once. The first call costs every candidate's compile time; ``.choice`` on the returned
      function maps each shape signature to the program picked.

    ``program=None`` keeps the older spelling working: ``fuse=False`` means ``"unfused"``, an
    explicit ``fuse=True`` or a ``batch_size`` means ``"blocks"``, otherwise ``"vmap"``.

    ``devices``: split the batch evenly over these devices (``shard_map``; a batch that does not
    divide is padded with its last item, and the padding dropped). XLA:CPU may not keep every
    core busy with one such program; to split it, start Python with
    ``XLA_FLAGS=--xla_force_host_platform_device_count=<cores>`` (before JAX is imported) and
    pass ``jax.devices()``. Keep ``fn`` free of LAPACK-backed calls there (Cholesky, solves,
    eigenvalues): with several CPU devices in one process, jaxlib 0.10's batched LAPACK kernels
    can wait forever on a thread pool the other device's kernel holds.

    The library's run-time checks inside ``fn`` (NaN/inf arguments, a singular mass matrix) are
    compiled as output flags, not as callbacks into Python: after each call the host raises the
    first failed check's :class:`jflex.DataError` / :class:`jflex.ParameterError`, naming the batch
    item (a GPU would otherwise hand control back to the host from inside the kernel). Called
    inside a caller's ``jit``, or where a check sits inside ``fn``'s own ``lax`` loop or
    derivative, the checks stay in the program as ``eqx.error_if``.

    Like :func:`sweep`, it calls :func:`jflex.tune_allocator` (``JFLEX_TUNE_ALLOCATOR=0`` opts out).
    """
    _tune_allocator_once()
    if program is None:
        program = "unfused" if fuse is False else "blocks" if (fuse is True or batch_size is not None) else "vmap"
    if program not in _PROGRAMS:
        raise ConfigError(f"batched: program must be one of {', '.join(map(repr, _PROGRAMS))}, got {program!r}")
    if batch_size is not None and int(batch_size) < 1:
        raise ShapeError(f"batched: batch_size must be >= 1, got {batch_size}")
    devices = list(devices) if devices is not None else []
    if program == "fastest":
        return _Fastest(fn, batch_size, devices)
    return _compile_program(fn, program, batch_size, devices)


def _compile_program(fn, program, batch_size, devices):
    """The batch program, with ``fn``'s run-time checks as output flags raised on the host
    (:class:`_Checked`); called with traced arguments (inside a caller's ``jit``), the checks stay
    inside the program as ``eqx.error_if``."""
    return _Checked(fn, functools.partial(_program, program=program, batch_size=batch_size, devices=devices))


# program="barriers": XLA:CPU expands optimization barriers away before its fusion pass; fusion then
# recomputes a body's shared work in every consumer (the Panda's ABA compiled to 1660 multiplies
# from 878). Kept through fusion, the kernels' per-body barriers bound the fusions, at the price of
# one compiled loop per fusion (100-300 instead of 1-20: longer compiles)
_KEEP_BARRIERS = {"xla_disable_hlo_passes": "cse_barrier_expander"}


def _vectorised(fn):
    """``fn`` traced with the kernels' arithmetic cosines and sines (see ``jflex/_trig.py``): a
    batch on CPU vectorises only without calls into the C library."""

    @functools.wraps(fn)
    def traced(*args):
        with vectorised():
            return fn(*args)

    return traced


def _on_cpu_vectorised(fn):
    """:func:`_vectorised` on CPU; elsewhere ``fn`` as it is (the library calls it avoids are XLA:CPU's)."""
    return _vectorised(fn) if jax.default_backend() == "cpu" else fn


def _program(fn, *, program, batch_size, devices, reduce=None, nested=False):
    """``nested``: for a call inside a caller's trace, where JAX takes no compiler options."""
    cpu = jax.default_backend() == "cpu" and not nested
    options = None if not cpu else {"unfused": {"xla_disable_hlo_passes": "fusion"}, "barriers": _KEEP_BARRIERS}.get(program)
    if program != "unfused":
        fn = _on_cpu_vectorised(fn)
    if program == "blocks":
        size = int(batch_size) if batch_size is not None else default_batch_size()

        def run(*args):
            return jax.lax.map(lambda a: fn(*a), args, batch_size=size)
    else:
        # ("unfused" never runs lax.map: XLA:CPU (jax 0.10.2) miscompiled lax.map's loop body without
        # fusion, RNEA and ABA came out wrong by O(1); tests/test_sweep_cli.py checks it)
        run = jax.vmap(fn)
    if len(devices) <= 1:
        return jax.jit(run if reduce is None else (lambda *a: reduce(run(*a))), compiler_options=options)
    nd = len(devices)
    spec = PartitionSpec("batch")
    sharded = jax.jit(jax.shard_map(run, mesh=Mesh(np.array(devices), ("batch",)), in_specs=spec, out_specs=spec,
                                    # (eqx.error_if checks inside fn: their cond branches carry no axis type)
                                    check_vma=False),
                      compiler_options=options)

    def split(*args):
        N = jax.tree_util.tree_leaves(args)[0].shape[0]
        pad = -N % nd
        if pad:
            args = jax.tree_util.tree_map(lambda a: jnp.concatenate([a, jnp.repeat(a[-1:], pad, axis=0)]), args)
        out = sharded(*args)
        out = jax.tree_util.tree_map(lambda a: a[:N], out) if pad else out
        return out if reduce is None else _reduce_jit(out)

    return split


def _flag_summary(out_flags):
    """``(out, any, first)``: per check, whether it failed for some item and the first such item."""
    out, flags = out_flags
    return out, jnp.any(flags, axis=0), jnp.argmax(flags, axis=0)


def _vmap_collected(fn, in_axes, *args):
    """``(out, any, first, messages)`` of ``vmap(fn)`` with fn's checks collected as flags
    (:func:`_flag_summary`); ``messages`` a tuple, a static output of an ``equinox.filter_jit``."""
    messages = []
    out, failed, first = _flag_summary(jax.vmap(_checks.collecting(fn, messages), in_axes=in_axes)(*args))
    return out, failed, first, tuple(messages)


_reduce_jit = jax.jit(_flag_summary)


def flagged_vmap(item_fn, in_axes=0):
    """``jit(vmap(item_fn, in_axes))`` with the library's checks inside ``item_fn`` as output flags
    raised on the host (see :class:`_Checked`): a program JAX's persistent compilation cache can
    store (it stores none that calls back into Python) and a GPU runs without handing control
    back to the host. Arguments are traced as ``equinox.filter_jit`` traces them."""

    @persistent_jit
    def program(*args):
        axes = in_axes if isinstance(in_axes, (tuple, list)) else (in_axes,) * len(args)
        # unmapped arguments are closed over, not passed through vmap: they may hold non-array leaves
        fixed = {i: a for i, (a, ax) in enumerate(zip(args, axes)) if ax is None}

        def item(*mapped):
            rest = iter(mapped)
            return item_fn(*(fixed[i] if i in fixed else next(rest) for i in range(len(args))))

        mapped_args = [a for i, a in enumerate(args) if i not in fixed]
        return _vmap_collected(item, [ax for ax in axes if ax is not None], *mapped_args)

    @functools.wraps(item_fn)
    def call(*args):
        out, failed, first, messages = program(*args)
        _raise_failed(failed, first, messages)
        return out

    return call


class _Checked:
    """A batch program whose checks (non-finite inputs, a singular mass matrix, ...) come back as
    flags: no callback into Python inside the compiled kernel (a GPU would stop for one on every
    call); the host raises the first failed check's message, with the item it failed for."""

    def __init__(self, fn, build):
        self._fn, self._build = fn, build
        self._messages: list = []
        self._flagged = None
        self._plain = self._nested = None

    def __call__(self, *args, start=0):
        """``start``: the index of the first item in a larger batch, for the failed check's message."""
        if any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(args)):
            if self._nested is None:
                self._nested = self._build(self._fn, nested=True)
            return self._nested(*args)
        if self._flagged is not False:
            if self._flagged is None:
                self._flagged = self._build(_checks.collecting(self._fn, self._messages), reduce=_flag_summary)
            try:
                out, failed, first = self._flagged(*args)
            except jax.errors.UnexpectedTracerError:
                # a check inside fn's own lax loop cannot leave it as a flag: keep error_if there
                self._flagged = False
            else:
                _raise_failed(failed, first, self._messages, start)
                return out
        if self._plain is None:
            self._plain = self._build(self._fn)
        return self._plain(*args)


class _Fastest:
    """``batched(program="fastest")``: picks, per argument signature, the program that timed fastest."""

    def __init__(self, fn, batch_size, devices):
        self._fn, self._batch_size, self._devices = fn, batch_size, devices
        self._programs = {}  # signature -> compiled callable
        self.choice = {}  # signature -> program name

    def __call__(self, *args, start=0):
        leaves, treedef = jax.tree_util.tree_flatten(args)
        sig = (treedef, tuple((np.shape(x), np.result_type(x).str) for x in leaves))
        run = self._programs.get(sig)
        if run is None:
            run = self._programs[sig] = self._pick(sig, args)
        return run(*args, start=start)

    def _pick(self, sig, args):
        names = ["vmap", "blocks"] + (["unfused", "barriers"] if jax.default_backend() == "cpu" else [])
        best, ref = None, None
        for name in names:
            run = _compile_program(self._fn, name, self._batch_size, self._devices)
            out = jax.block_until_ready(run(*args))  # compiles
            flat = [np.asarray(o) for o in jax.tree_util.tree_leaves(out)]
            if ref is None:
                ref = flat
            elif not all(_close(a, b) for a, b in zip(flat, ref)):
                continue  # a program that disagrees with the fused vmap is never chosen
            t0 = time.perf_counter()
            jax.block_until_ready(run(*args))
            t = time.perf_counter() - t0
            if best is None or t < best[0]:
                best = (t, name, run)
        self.choice[sig] = best[1]
        return best[2]


def _close(a, b) -> bool:
    scale = float(np.max(np.abs(b), initial=0.0, where=np.isfinite(b))) if b.size else 0.0
    return a.shape == b.shape and bool(np.allclose(a, b, rtol=0.0, atol=1e-9 * scale, equal_nan=True))


# ---- sweep's compiled program, reused across calls --------------------------------------------
# jax.jit caches a program per function object, and sweep used to wrap a fresh jax.vmap(fn) on
# every call: every call compiled again. A function is split instead into a hashable template (its
# code, or the function itself) and the values it closes over (closure cells, defaults,
# functools.partial arguments, a bound method's object), and one module-level jitted program takes
# the values as arguments: arrays in them are traced, so a second sweep of the same code over a
# robot with other numbers (same shapes) reuses the compiled program.


class _Code:
    """A closure's code and globals (hashable): with its cells and defaults it is the function."""

    __slots__ = ("code", "globals", "name", "kwdefaults")

    def __init__(self, fn):
        self.code, self.globals, self.name, self.kwdefaults = fn.__code__, fn.__globals__, fn.__name__, fn.__kwdefaults__

    def __hash__(self):
        return hash((self.code, id(self.globals)))

    def __eq__(self, other):
        return isinstance(other, _Code) and self.code is other.code and self.globals is other.globals

    def _content_key(self):  # for the traced-program cache (jflex/_program_cache.py)
        return self.globals.get("__name__"), self.code.co_qualname, self.code.co_firstlineno, self.kwdefaults

    def build(self, cells, defaults):
        f = types.FunctionType(self.code, self.globals, self.name, defaults, tuple(types.CellType(c) for c in cells))
        f.__kwdefaults__ = self.kwdefaults
        return f


def _split(fn):
    """``(template, values)`` with ``_rebuild(template, values)`` equivalent to ``fn``."""
    if isinstance(fn, functools.partial):
        t, v = _split(fn.func)
        return ("partial", t, tuple(fn.keywords)), (v, fn.args, tuple(fn.keywords.values()))
    if isinstance(fn, types.MethodType):
        t, v = _split(fn.__func__)
        return ("method", t), (v, fn.__self__)
    if isinstance(fn, types.FunctionType) and (fn.__closure__ or fn.__defaults__) and not fn.__kwdefaults__:
        try:
            cells = tuple(c.cell_contents for c in fn.__closure__ or ())
        except ValueError:  # an empty cell (a name assigned after the function was made)
            return ("fn", fn), ()
        return ("code", _Code(fn)), (cells, fn.__defaults__)
    return ("fn", fn), ()


def _rebuild(template, values):
    kind = template[0]
    if kind == "partial":
        inner, args, kwvalues = values
        return functools.partial(_rebuild(template[1], inner), *args, **dict(zip(template[2], kwvalues)))
    if kind == "method":
        inner, obj = values
        return types.MethodType(_rebuild(template[1], inner), obj)
    if kind == "code":
        cells, defaults = values
        return template[1].build(cells, defaults)
    return template[1]


@persistent_jit
def _vmapped(template, values, *items):
    return jax.vmap(_on_cpu_vectorised(_rebuild(template, values)))(*items)


@persistent_jit
def _vmapped_flagged(template, values, *items):
    """:func:`_vmapped` with fn's checks as flags (see :class:`_Checked`); the messages are a static
    output, kept by ``filter_jit`` with the compiled program."""
    return _vmap_collected(_on_cpu_vectorised(_rebuild(template, values)), 0, *items)


def _raise_failed(failed, first, messages, start=0):
    """Raise the first failed check's message, naming the item it failed for (``start``: the
    index of the batch's first item in the whole sweep; see :class:`_Checked`)."""
    failed = np.asarray(failed)
    if failed.any():
        k = int(np.argmax(failed))
        # the guards check inputs (NaN/inf: the data) or the robot (a singular mass matrix)
        kind = DataError if "NaN/inf" in messages[k] else ParameterError
        raise kind(f"{messages[k]} (batch item {start + int(np.asarray(first)[k])}, the first of the items this "
                   "check failed for)")


def _hashable(tree) -> bool:
    """Whether eqx.filter_jit can key on the non-array parts of ``tree`` (it hashes them)."""
    try:
        hash(jax.tree_util.tree_structure(tree))
        for leaf in jax.tree_util.tree_leaves(tree):
            if not eqx.is_array(leaf):
                hash(leaf)
        return True
    except TypeError:
        return False


_FALLBACK: dict = {}  # fn -> eqx.filter_jit(jax.vmap(_on_cpu_vectorised(fn))), checks as error_if
_FALLBACK_SIZE = 32


_TRACE_ERRORS = (jax.errors.ConcretizationTypeError, jax.errors.TracerBoolConversionError,
                 jax.errors.TracerIntegerConversionError, jax.errors.TracerArrayConversionError)


# The values a function closes over (a robot) are compiled as constants while one set of them is
# swept: XLA folds them (a URDF's right-angle joint placements are mostly exact zeros and ones), and
# the Panda's batched RNEA ran 2.3x faster so (0.25 against 0.59 us a state). Once the same code
# comes with other values (an identification sweeping robots), one program taking them as
# arguments is compiled and serves every later set; values too large to embed are arguments always.
_CONSTANT_LIMIT = 1 << 16  # array elements in the closed-over values
_FIRST_VALUES: dict = {}  # template -> fingerprint of the first values swept with it
_CONSTANT: dict = {}  # (template, fingerprint) -> flagged program with the values as constants
_CONSTANT_SIZE = 32


def _constant_key(template, values):
    """The fingerprint of ``values`` when they may be compiled as constants, else ``None``."""
    leaves = jax.tree_util.tree_leaves(values)
    if any(isinstance(x, jax.core.Tracer) for x in leaves):
        return None
    if sum(int(np.size(x)) for x in leaves if eqx.is_array(x)) > _CONSTANT_LIMIT:
        return None
    key = fingerprint(values)
    first = _FIRST_VALUES.setdefault(template, key)
    return key if first == key else None


def _flagged_constant(fn):
    @persistent_jit
    def program(*items):
        return _vmap_collected(_on_cpu_vectorised(fn), 0, *items)

    return program


def _sweep_program(fn, one_item):
    """A callable ``items -> vmapped fn(items)`` whose compiled program outlives this sweep.

    ``fn`` is first traced once as it is (``one_item``: shapes of one item; no compilation), so
    the checks jflex makes on values known at trace time (a robot without inertia, a
    non-physical parameter) raise as they would in a plain call, before the values become
    arguments of the shared program. Where ``fn`` needs its closed-over values concrete (Python
    control flow on them), it is compiled with them as constants, as before."""
    jax.eval_shape(fn, *one_item)
    template, values = _split(fn)
    if _hashable(template) and _hashable(values):
        key = _constant_key(template, values)
        if key is not None:
            program = _CONSTANT.get((template, key))
            if program is None:
                if len(_CONSTANT) >= _CONSTANT_SIZE:
                    _CONSTANT.pop(next(iter(_CONSTANT)))
                program = _CONSTANT[(template, key)] = _flagged_constant(fn)
            shared, flagged = _constant_program(fn), True
        else:
            shared, flagged = functools.partial(_vmapped, template, values), True
            program = functools.partial(_vmapped_flagged, template, values)

        def run(*items, start=0):
            nonlocal shared, flagged
            if shared is not None:
                try:
                    if flagged:
                        out, failed, first, messages = program(*items)
                        _raise_failed(failed, first, messages, start)
                        return out
                    return shared(*items)
                except jax.errors.UnexpectedTracerError:
                    # a check inside fn's own lax loop cannot leave it as a flag: keep error_if there
                    flagged = False
                    return run(*items)
                except _TRACE_ERRORS:
                    shared = None
            return _constant_program(fn)(*items)

        return run
    program = _constant_program(fn)
    return lambda *items, start=0: program(*items)


def _constant_program(fn):
    try:
        return _FALLBACK[fn]
    except TypeError:  # an unhashable callable object: compiled for this call only
        return eqx.filter_jit(jax.vmap(_on_cpu_vectorised(fn)))
    except KeyError:
        if len(_FALLBACK) >= _FALLBACK_SIZE:
            _FALLBACK.pop(next(iter(_FALLBACK)))
        prog = _FALLBACK[fn] = eqx.filter_jit(jax.vmap(_on_cpu_vectorised(fn)))
        return prog


def _default_devices():
    """``jax.devices()`` with one CPU device per process (see ``sweep``'s ``devices``)."""
    out, seen = [], set()
    for d in jax.devices():
        if d.platform == "cpu":
            if d.process_index in seen:
                continue
            seen.add(d.process_index)
        out.append(d)
    return out


def sweep(
    fn: Callable,
    *args,
    chunk_size: int = 4096,
    progress: bool = True,
    on_chunk: Callable | None = None,
    out_dir: str | os.PathLike | None = None,
    devices=None,
    label: str = "sweep",
    key=None,
    program: str | None = None,
):
    """Evaluate ``fn`` (one item, no batch dimension) over the leading axis of ``args``.

    **Arguments:**

    - ``fn``: ``fn(*items) -> pytree`` for one item. Closed-over models are constants; pass
      them as a non-batched argument via ``functools.partial`` or a closure.
    - ``args``: pytrees of arrays sharing a leading batch axis of size N.
    - ``chunk_size``: items per compiled call (memory is bounded by one chunk).
    - ``progress``: progress on stderr (a tqdm bar on a terminal; otherwise a plain line at the start,
      at most every 5 s, and at the end).
    - ``on_chunk``: ``on_chunk(start, stop, outputs)`` called with host (NumPy) outputs of each
      finished chunk.
    - ``out_dir``: if given, each finished chunk is saved as ``out_dir/chunk_<start>.npz`` at
      once (atomically: a temporary file renamed into place), and chunks already there are loaded
      instead of recomputed (resume). Each chunk and the folder's ``sweep.json`` carry a
      fingerprint of the inputs, the function (qualified name, bytecode and the arrays and
      pytrees it closes over, e.g. a robot), the chunk size and ``key``; a folder written by a
      different sweep, or a damaged chunk, raises :class:`jflex.DataError` naming the file, and
      nothing in it is reused (clear the folder or pass another ``out_dir``).
    - ``devices``: devices to shard each chunk over. Default: every device of ``jax.devices()``,
      except that on CPU each process contributes one device: one XLA:CPU device already spreads a
      chunk over the cores, and with several CPU devices in one process jaxlib 0.10's batched
      LAPACK kernels (Cholesky, triangular solves, eigenvalues) can wait forever on a thread
      pool the other device's kernel holds (seen with ``forward_dynamics(method="crba")`` on 2
      cores). Pass ``jax.devices()`` to split over them anyway.
    - ``key``: anything whose ``repr`` tells this sweep apart when the fingerprint cannot see a
      change (a model read from a file inside ``fn``, an object attribute it reads).
    - ``program``: how each chunk is compiled, as in :func:`batched` (``"vmap"``, ``"blocks"``,
      ``"unfused"``, ``"barriers"``, ``"fastest"``). Default: one vmapped program with the
      closed-over values folded in as constants (below), kept across sweeps.

    **Returns:** the outputs for all N items as NumPy arrays (same pytree structure as ``fn``'s).
    An empty batch (N = 0) returns empty arrays: leading axis 0, then the shape and dtype ``fn``
    gives one item (``fn`` is traced once, never run; nothing is written to ``out_dir``).

    As in :func:`batched`, the library's run-time checks inside ``fn`` are output flags of the
    compiled program, raised on the host after each chunk with the index of the first failing item.

    The compiled program is kept: a second ``sweep`` of the same function reuses it. The values
    ``fn`` closes over (a robot) are compiled in as constants, which XLA folds (the Panda's RNEA
    runs about twice as fast so); once a new closure or ``functools.partial`` of the same code
    comes with other arrays of the same shapes (another robot's numbers), one program taking them
    as arguments is compiled, and every later set of numbers reuses it.

    Calls :func:`jflex.tune_allocator` first (``JFLEX_TUNE_ALLOCATOR=0`` opts out): each chunk's
    outputs are then served from reused heap memory instead of fresh pages.
    """
    _tune_allocator_once()
    leaves = jax.tree_util.tree_leaves(args)
    if not leaves:
        raise ShapeError("sweep: needs at least one batched array argument")
    N = int(np.shape(leaves[0])[0])
    for leaf in leaves:
        if np.ndim(leaf) == 0 or np.shape(leaf)[0] != N:
            raise ShapeError(f"sweep: every batched argument needs leading axis {N}, got shape {np.shape(leaf)}")
    if chunk_size < 1:
        raise ShapeError(f"sweep: chunk_size must be >= 1, got {chunk_size}")
    if program is not None and program not in _PROGRAMS:
        raise ConfigError(f"sweep: program must be None or one of {', '.join(map(repr, _PROGRAMS))}, got {program!r}")
    out_path = _out_folder(out_dir)
    if N == 0:
        # an empty batch maps to empty outputs, as a NumPy function over an empty array does:
        # every output leaf has leading axis 0 and the item shape and dtype fn gives one item
        items = jax.tree_util.tree_map(lambda a: jax.ShapeDtypeStruct(np.shape(a)[1:], np.result_type(a)), args)
        shapes = jax.eval_shape(fn, *items)
        return jax.tree_util.tree_map(lambda s: np.zeros((0, *s.shape), s.dtype), shapes)
    devices = list(devices) if devices is not None else _default_devices()
    nd = len(devices)
    chunk = min(chunk_size, N)
    chunk = int(math.ceil(chunk / nd) * nd)  # every device gets the same share
    # devices of several processes (jax.distributed): collective loads and gathers below
    multi = any(d.process_index != jax.process_index() for d in devices)
    mesh = Mesh(np.array(devices), ("batch",))
    sharding = NamedSharding(mesh, PartitionSpec("batch"))
    if program is None:
        vfn = _sweep_program(fn, jax.tree_util.tree_map(lambda a: jax.ShapeDtypeStruct(np.shape(a)[1:], np.result_type(a)), args))
    else:  # the user's choice of batch program
        vfn = batched(fn, program=program)

    if out_path is not None:
        identity = _identity(fn, args, N, chunk, key)
        _check_manifest(out_path, identity)
    treedef = None
    pieces = []
    with bar(N, label, progress) as shown_bar:
        for start in range(0, N, chunk):
            stop = min(start + chunk, N)
            cached = out_path / f"chunk_{start:09d}.npz" if out_path is not None else None
            have = cached is not None and cached.exists()
            if multi:
                # every process runs every chunk's program together: load a chunk only if every
                # process has it (a process killed between two saves would otherwise wait alone)
                have = bool(np.all(multihost_utils.process_allgather(np.array(have))))
            if have:
                flat = _load_chunk(cached, _chunk_fingerprint(identity, start, stop), out_path)
                if treedef is None:
                    treedef = jax.tree_util.tree_structure(jax.eval_shape(jax.vmap(fn), *jax.tree_util.tree_map(lambda a: a[:1], args)))
                host = jax.tree_util.tree_unflatten(treedef, flat)
            else:
                pad = chunk - (stop - start)

                def take(a):
                    # several processes pass the same host values; a host array is cut on the host
                    # (jnp's slicing and padding are programs of their own, compiled per shape)
                    xp = np if multi or not isinstance(a, jax.Array) else jnp
                    a = xp.asarray(a[start:stop])
                    if pad:  # repeat the last item so every chunk has one compiled shape
                        a = xp.concatenate([a, xp.repeat(a[-1:], pad, axis=0)])
                    return jax.device_put(a, sharding)

                out = vfn(*jax.tree_util.tree_map(take, args), start=start)
                if multi:  # the chunk's outputs live on every process's devices: gather them
                    out = multihost_utils.process_allgather(out, tiled=True)
                host = jax.tree_util.tree_map(lambda a: np.asarray(a)[: stop - start], out)
                flat, treedef = jax.tree_util.tree_flatten(host)
                if cached is not None:
                    _save_chunk(cached, flat, _chunk_fingerprint(identity, start, stop))
            if on_chunk is not None:
                on_chunk(start, stop, host)
            pieces.append(host)
            shown_bar.update(stop - start)
    return jax.tree_util.tree_map(lambda *xs: np.concatenate(xs, axis=0), *pieces)


# ---- resumable chunks: fingerprints, atomic writes, refusal of anything stale ----------------


def _out_folder(out_dir):
    """``out_dir`` as a folder that exists, or a :class:`ConfigError` naming it."""
    return None if out_dir is None else output_folder(out_dir, "sweep: out_dir")


def _identity(fn, args, N, chunk, key) -> dict:
    """What makes two sweeps the same: each part hashed separately so a mismatch can be named."""
    return {
        "format": 1,
        "function": f"{getattr(fn, '__module__', '?')}.{getattr(fn, '__qualname__', type(fn).__name__)}",
        "function_hash": fingerprint(fn),
        "inputs_hash": fingerprint(args),
        "items": N,
        "chunk_size": chunk,
        "key": repr(key),
    }


def _chunk_fingerprint(identity: dict, start: int, stop: int) -> str:
    return fingerprint(json.dumps(identity, sort_keys=True), start, stop)


def _clear_hint(out_path) -> str:
    return f"clear the folder {out_path} (or pass another out_dir) to recompute; nothing in it was reused"


def _atomic_write(path: pathlib.Path, write) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with open(tmp, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def _check_manifest(out_path: pathlib.Path, identity: dict) -> None:
    """Refuse a folder written by another sweep (or by a jflex without fingerprints); start a new
    folder's manifest."""
    manifest = out_path / _MANIFEST
    chunks = sorted(out_path.glob("chunk_*.npz"))
    if not manifest.exists():
        if chunks:
            raise DataError(
                f"sweep: {chunks[0]} has no fingerprint ({out_path / _MANIFEST} is missing: written by an older jflex "
                f"or another program), so it cannot be told apart from a stale result; {_clear_hint(out_path)}"
            )
        _atomic_write(manifest, lambda f: f.write(json.dumps(identity, indent=1).encode()))
        return
    try:
        old = json.loads(manifest.read_text())
    except (OSError, ValueError) as exc:
        raise DataError(f"sweep: {manifest} is damaged ({exc}); {_clear_hint(out_path)}") from None
    diff = [k for k in identity if old.get(k) != identity[k]]
    if diff:
        what = ", ".join(
            f"{k} {old.get(k)} -> {identity[k]}" if not k.endswith("_hash") else _CHANGED[k] for k in diff
        )
        raise DataError(
            f"sweep: {out_path} holds the chunks of a different sweep ({what}): resuming would mix stale results "
            f"with new ones; {_clear_hint(out_path)}"
        )


def _save_chunk(path: pathlib.Path, flat, fp: str) -> None:
    arrays = {f"leaf{k}": v for k, v in enumerate(flat)}
    arrays[_FP_KEY] = np.array(fp)
    _atomic_write(path, lambda f: np.savez(f, **arrays))


def _load_chunk(path: pathlib.Path, fp: str, out_path) -> list:
    try:
        with np.load(path, allow_pickle=False) as data:
            stored = str(data[_FP_KEY]) if _FP_KEY in data.files else None
            leaves = sorted((f for f in data.files if f != _FP_KEY), key=lambda f: int(f[4:]))
            flat = [data[f] for f in leaves]
    except (zipfile.BadZipFile, OSError, ValueError, EOFError, KeyError) as exc:
        raise DataError(f"sweep: {path} is damaged ({type(exc).__name__}: {exc}); {_clear_hint(out_path)}") from None
    if stored != fp:
        raise DataError(
            f"sweep: {path} was written by a different sweep (its fingerprint does not match this call's inputs, "
            f"function, chunk size and key); {_clear_hint(out_path)}"
        )
    return flat
