"""Batch evaluation of a per-item function over a large batch: chunked (bounded memory), sharded
across ``jax.devices()``, with progress and per-chunk files so an interrupted sweep keeps what it
has already computed and resumes where it stopped.

Several hosts: start the same script on every host after
``jax.distributed.initialize(coordinator_address, num_processes, process_id)``; ``jax.devices()``
then lists every host's devices and the same ``sweep`` call shards each chunk across all of them
(give each process its own ``out_dir`` or let process 0 write, see the README).
"""

from __future__ import annotations

import json
import math
import os
import pathlib
import zipfile
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from ._allocator import tune_allocator
from ._errors import DataError, ShapeError
from ._fingerprint import fingerprint
from ._progress import bar

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


def batched(fn: Callable, *, batch_size: int = 1024, fuse: bool = True, devices=None):
    """A jitted batch version of a per-item ``fn``: evaluates it over the leading axis of its
    arguments in blocks of ``batch_size`` (``lax.map``), so the working set of each block stays
    in cache however large the batch.

    ``fuse=False`` compiles one vmapped program without XLA's fusion pass (CPU only; no blocks),
    which is fastest for the long elementwise rigid-body kernels ``rnea``, ``crba`` and ``aba``
    (measured in ``benchmarks/bench_dynamics.py``, checked against Pinocchio in the tests). Keep
    the default ``True`` for anything else: on jax 0.10.2, XLA:CPU without fusion also returned
    wrong results for other programs (lax.map blocks; a modal linearisation's mass matrix).

    ``devices``: split the batch evenly over these devices (``shard_map``; a batch that does not
    divide is padded with its last item, and the padding dropped). XLA:CPU runs one such program
    on one core; to use several cores, start Python with
    ``XLA_FLAGS=--xla_force_host_platform_device_count=<cores>`` (before JAX is imported) and
    pass ``jax.devices()``.

    Like :func:`sweep`, it calls :func:`jflex.tune_allocator` (``JFLEX_TUNE_ALLOCATOR=0`` opts out).
    """
    _tune_allocator_once()
    cpu_unfused = not fuse and jax.default_backend() == "cpu"
    options = {"xla_disable_hlo_passes": "fusion"} if cpu_unfused else None
    if cpu_unfused:
        # one vmapped program, no lax.map blocks: XLA:CPU (jax 0.10.2) miscompiles lax.map's loop
        # body when fusion is off (RNEA and ABA came out wrong by O(1); crba did not), which
        # tests/test_sweep_cli.py checks against the fused program
        run = jax.vmap(fn)
    else:

        def run(*args):
            return jax.lax.map(lambda a: fn(*a), args, batch_size=batch_size)

    devices = list(devices) if devices is not None else []
    if len(devices) <= 1:
        return jax.jit(run, compiler_options=options)
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
        return jax.tree_util.tree_map(lambda a: a[:N], out) if pad else out

    return split


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
):
    """Evaluate ``fn`` (one item, no batch dimension) over the leading axis of ``args``.

    **Arguments:**

    - ``fn``: ``fn(*items) -> pytree`` for one item. Closed-over models are constants; pass
      them as a non-batched argument via ``functools.partial`` or a closure.
    - ``args``: pytrees of arrays sharing a leading batch axis of size N.
    - ``chunk_size``: items per compiled call (memory is bounded by one chunk).
    - ``progress``: a progress bar on stderr (tqdm; drawn only when stderr is a terminal).
    - ``on_chunk``: ``on_chunk(start, stop, outputs)`` called with host (NumPy) outputs of each
      finished chunk.
    - ``out_dir``: if given, each finished chunk is saved as ``out_dir/chunk_<start>.npz`` at
      once (atomically: a temporary file renamed into place), and chunks already there are loaded
      instead of recomputed (resume). Each chunk and the folder's ``sweep.json`` carry a
      fingerprint of the inputs, the function (qualified name, bytecode and the arrays and
      pytrees it closes over, e.g. a robot), the chunk size and ``key``; a folder written by a
      different sweep, or a damaged chunk, raises :class:`jflex.DataError` naming the file, and
      nothing in it is reused (clear the folder or pass another ``out_dir``).
    - ``devices``: devices to shard each chunk over (default ``jax.devices()``).
    - ``key``: anything whose ``repr`` tells this sweep apart when the fingerprint cannot see a
      change (a model read from a file inside ``fn``, an object attribute it reads).

    **Returns:** the outputs for all N items as NumPy arrays (same pytree structure as ``fn``'s).

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
    devices = list(devices) if devices is not None else jax.devices()
    nd = len(devices)
    chunk = min(chunk_size, N)
    chunk = int(math.ceil(chunk / nd) * nd)  # every device gets the same share
    mesh = Mesh(np.array(devices), ("batch",))
    sharding = NamedSharding(mesh, PartitionSpec("batch"))
    vfn = eqx.filter_jit(jax.vmap(fn))

    out_path = pathlib.Path(out_dir) if out_dir is not None else None
    if out_path is not None:
        out_path.mkdir(parents=True, exist_ok=True)
        identity = _identity(fn, args, N, chunk, key)
        _check_manifest(out_path, identity)
    treedef = None
    pieces = []
    with bar(N, label, progress) as shown_bar:
        for start in range(0, N, chunk):
            stop = min(start + chunk, N)
            cached = out_path / f"chunk_{start:09d}.npz" if out_path is not None else None
            if cached is not None and cached.exists():
                flat = _load_chunk(cached, _chunk_fingerprint(identity, start, stop), out_path)
                if treedef is None:
                    treedef = jax.tree_util.tree_structure(jax.eval_shape(jax.vmap(fn), *jax.tree_util.tree_map(lambda a: a[:1], args)))
                host = jax.tree_util.tree_unflatten(treedef, flat)
            else:
                pad = chunk - (stop - start)

                def take(a):
                    a = jnp.asarray(a[start:stop])
                    if pad:  # repeat the last item so every chunk has one compiled shape
                        a = jnp.concatenate([a, jnp.repeat(a[-1:], pad, axis=0)])
                    return jax.device_put(a, sharding)

                out = vfn(*jax.tree_util.tree_map(take, args))
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
