"""Batch evaluation of a per-item function over a large batch: chunked (bounded memory), sharded
across ``jax.devices()``, with progress and per-chunk files so an interrupted sweep keeps what it
has already computed and resumes where it stopped.

Several hosts: start the same script on every host after
``jax.distributed.initialize(coordinator_address, num_processes, process_id)``; ``jax.devices()``
then lists every host's devices and the same ``sweep`` call shards each chunk across all of them
(give each process its own ``out_dir`` or let process 0 write, see the README).
"""

from __future__ import annotations

import math
import os
import pathlib
import sys
import time
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from ._allocator import tune_allocator
from ._errors import ShapeError


def _tune_allocator_once():
    # batch outputs of a few MB per call otherwise page-fault afresh on many calls (see
    # jflex/_allocator.py); JFLEX_TUNE_ALLOCATOR=0 leaves glibc's defaults
    if os.environ.get("JFLEX_TUNE_ALLOCATOR", "1") != "0":
        tune_allocator()


def _progress(done, total, t0, label):
    frac = done / total
    el = time.perf_counter() - t0
    eta = el / frac - el if frac > 0 else float("nan")
    bar = "#" * int(30 * frac) + "." * (30 - int(30 * frac))
    sys.stderr.write(f"\r{label} [{bar}] {done}/{total} ({el:.1f}s, eta {eta:.1f}s)")
    if done == total:
        sys.stderr.write("\n")
    sys.stderr.flush()


def batched(fn: Callable, *, batch_size: int = 1024, fuse: bool = True):
    """A jitted batch version of a per-item ``fn``: evaluates it over the leading axis of its
    arguments in blocks of ``batch_size`` (``lax.map``), so the working set of each block stays
    in cache however large the batch.

    ``fuse=False`` compiles one vmapped program without XLA's fusion pass (CPU only; no blocks),
    which is fastest for the long elementwise rigid-body kernels ``rnea``, ``crba`` and ``aba``
    (measured in ``benchmarks/bench_dynamics.py``, checked against Pinocchio in the tests). Keep
    the default ``True`` for anything else: on jax 0.10.2, XLA:CPU without fusion also returned
    wrong results for other programs (lax.map blocks; a modal linearisation's mass matrix).

    Like :func:`sweep`, it calls :func:`jflex.tune_allocator` (``JFLEX_TUNE_ALLOCATOR=0`` opts out).
    """
    _tune_allocator_once()
    if not fuse and jax.default_backend() == "cpu":
        # one vmapped program, no lax.map blocks: XLA:CPU (jax 0.10.2) miscompiles lax.map's loop
        # body when fusion is off (RNEA and ABA came out wrong by O(1); crba did not), which
        # tests/test_sweep_cli.py checks against the fused program
        return jax.jit(jax.vmap(fn), compiler_options={"xla_disable_hlo_passes": "fusion"})

    def run(*args):
        return jax.lax.map(lambda a: fn(*a), args, batch_size=batch_size)

    return jax.jit(run)


def sweep(
    fn: Callable,
    *args,
    chunk_size: int = 4096,
    progress: bool = True,
    on_chunk: Callable | None = None,
    out_dir: str | os.PathLike | None = None,
    devices=None,
    label: str = "sweep",
):
    """Evaluate ``fn`` (one item, no batch dimension) over the leading axis of ``args``.

    **Arguments:**

    - ``fn``: ``fn(*items) -> pytree`` for one item. Closed-over models are constants; pass
      them as a non-batched argument via ``functools.partial`` or a closure.
    - ``args``: pytrees of arrays sharing a leading batch axis of size N.
    - ``chunk_size``: items per compiled call (memory is bounded by one chunk).
    - ``progress``: print a progress bar to stderr.
    - ``on_chunk``: ``on_chunk(start, stop, outputs)`` called with host (NumPy) outputs of each
      finished chunk.
    - ``out_dir``: if given, each finished chunk is saved as ``out_dir/chunk_<start>.npz`` at
      once, and chunks already there are loaded instead of recomputed (resume).
    - ``devices``: devices to shard each chunk over (default ``jax.devices()``).

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
    treedef = None
    pieces = []
    t0 = time.perf_counter()
    for start in range(0, N, chunk):
        stop = min(start + chunk, N)
        cached = out_path / f"chunk_{start:09d}.npz" if out_path is not None else None
        if cached is not None and cached.exists():
            with np.load(cached) as data:
                flat = [data[f"leaf{k}"] for k in range(len(data.files))]
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
                tmp = cached.with_name(cached.stem + ".tmp.npz")
                np.savez(tmp, **{f"leaf{k}": v for k, v in enumerate(flat)})
                os.replace(tmp, cached)
        if on_chunk is not None:
            on_chunk(start, stop, host)
        pieces.append(host)
        if progress:
            _progress(stop, N, t0, label)
    return jax.tree_util.tree_map(lambda *xs: np.concatenate(xs, axis=0), *pieces)
