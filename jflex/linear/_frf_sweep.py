"""FRFs over a posture sweep in two stages: eigenproblems in large batches, FRF arrays in small
blocks.

The two halves of a modal FRF want opposite batch sizes on a CPU. The linearisation and the
eigenproblem are a few hundred small fused loops whose per-call cost is spread over the batch
(4-6 us per posture at 1e3-1e4 postures against ~9 at 64, measured on the 3-joint arm of
``benchmarks/bench_modal.py``). The synthesised FRF is 73 kB per posture (512 frequencies,
3x3 complex), so it stays in cache only in blocks of a few tens of postures (a block of 64 is
1.5-2x faster than one of 256-1024 there). :func:`frf_sweep` therefore solves the
:class:`~jflex.linear.PoleResidue` models chunk by chunk and synthesises each chunk's FRFs
block by block.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._compiled import QUICK_COMPILE, compiled
from .._errors import ShapeError
from .._model import Model
from .._progress import bar
from .._sweep import _tune_allocator_once
from ._common import check_frequencies
from ._frf import _check_kind_method, frf, pole_residue, synthesize_frf


def _padded(a, n):
    # repeat the last item so every call has one compiled shape
    pad = n - a.shape[0]
    return a if pad == 0 else jnp.concatenate([a, jnp.repeat(a[-1:], pad, axis=0)])


# module-level programs (the model's numbers traced, its structure, the robot's kinematics and
# the options static, see jflex._compiled): repeated sweeps over the same robot and model
# structure reuse one compilation
def _poles_of(model, Q, kw):
    return jax.vmap(lambda q: pole_residue(model, q, **dict(kw)))(Q)


_poles = compiled(_poles_of)
# The same programs compiled without LLVM's optimisation passes (both stages): on the flexible-
# joint Panda (14 coordinates, 200 frequencies) a first call of 64 postures took 7.2 s against
# 14.3-15.2 s, and 1024 postures then ran in 1.47 against 0.87 s (load 2-3 on 2 cores): about
# 0.6 ms a posture more for some 8 s less compilation. Sweeps up to QUICK_COMPILE_POSTURES use
# them, where the slower run costs at most ~1.2 s even once a compilation cache has the
# optimised program.
_poles_quick = compiled(_poles_of, compiler_options=QUICK_COMPILE)
QUICK_COMPILE_POSTURES = 2048


# jax.jit rather than eqx.filter_jit, and the block sliced inside: one cheap dispatch per block
# (~20 us against ~45 us plus two eager slices, per 64 postures)
def _synthesize_of(items, start, omega, kind, block):
    sub = jax.tree_util.tree_map(lambda a: jax.lax.dynamic_slice_in_dim(a, start, block), items)
    return jax.vmap(lambda pr: synthesize_frf(pr, omega, kind=kind))(sub)


_synthesize = functools.partial(jax.jit, static_argnames=("kind", "block"))(_synthesize_of)
_synthesize_quick = functools.partial(jax.jit, static_argnames=("kind", "block"),
                                      compiler_options=QUICK_COMPILE)(_synthesize_of)


@eqx.filter_jit
def _direct(model, Q, omega, kind, kw):
    return jax.vmap(lambda q: frf(model, q, omega, kind=kind, method="direct", **dict(kw)))(Q)


def frf_sweep(
    model: Model,
    postures,
    omega,
    *,
    hold=(),
    frame=None,
    reference: str = "local_world_aligned",
    components: str = "linear",
    kind: str = "receptance",
    method: str = "modal",
    solver: str = "newton",
    chunk_size: int = 4096,
    block_size: int = 64,
    consume: Callable | None = None,
    progress: bool = True,
    label: str = "frf_sweep",
):
    """FRFs of ``model`` at every posture of ``postures`` (N, n) on the grid ``omega`` (nf,).

    **Arguments:**

    - ``model``, ``hold``, ``frame``, ``reference``, ``components``, ``kind``, ``solver``: as in
      :func:`jflex.frf`.
    - ``method``: ``"modal"`` (default; viscous models with underdamped modes): the
      :class:`~jflex.linear.PoleResidue` models are solved ``chunk_size`` postures per call and
      the FRFs synthesised ``block_size`` postures per call. ``"direct"``: :func:`jflex.frf`'s
      direct form (any effect, e.g. hysteretic or fractional damping), ``block_size`` per call.
    - ``consume``: ``consume(start, H)`` receives each finished block, ``H`` (b, nf, p, p) a
      NumPy array for postures ``start:start + b``, valid during the call only (copy what you
      keep). Without it the result is returned whole.
    - ``progress``: progress on stderr (a tqdm bar on a terminal; otherwise a plain line at the start,
      at most every 5 s, and at the end).

    **Returns:** complex (N, nf, p, p) NumPy array, or None when ``consume`` is given.
    Calls :func:`jflex.tune_allocator` first (``JFLEX_TUNE_ALLOCATOR=0`` opts out).
    """
    _check_kind_method(kind, method)
    omega = check_frequencies(omega)
    Q = jnp.asarray(postures, dtype=float)
    if Q.ndim != 2 or Q.shape[0] == 0:
        raise ShapeError(f"frf_sweep: postures must be (N, n) with N >= 1, got shape {Q.shape}")
    for name, v in (("chunk_size", chunk_size), ("block_size", block_size)):
        if int(v) != v or v < 1:
            raise ShapeError(f"frf_sweep: {name} must be a positive integer, got {v!r}")
    _tune_allocator_once()
    N = Q.shape[0]
    block = min(block_size, N)
    # equal chunks of whole blocks: the last chunk's padding stays under one block per chunk
    n_chunks = -(-N // max(block, chunk_size // block * block))
    chunk = -(-(-(-N // n_chunks)) // block) * block
    hold = hold if isinstance(hold, str) else tuple(hold)
    kw = (("hold", hold), ("frame", frame), ("reference", reference), ("components", components), ("solver", solver))
    if method == "modal":
        quick = N <= QUICK_COMPILE_POSTURES
        poles, synthesize = (_poles_quick, _synthesize_quick) if quick else (_poles, _synthesize)
        stage1 = lambda Qc: poles(model, Qc, kw)
        stage2 = lambda items, start: synthesize(items, start, omega, kind, block)
    else:
        stage1 = lambda Qc: Qc
        stage2 = lambda Qc, start: _direct(model, jax.lax.dynamic_slice_in_dim(Qc, start, block), omega, kind, kw)
    out = None

    def finish(b0, b1, H):
        nonlocal out
        H = np.asarray(H)[: b1 - b0]
        if consume is not None:
            consume(b0, H)
            return
        if out is None:
            out = np.empty((N,) + H.shape[1:], H.dtype)
        out[b0:b1] = H

    pending = None
    with bar(N, label, progress, unit="posture") as shown_bar:
        for c0 in range(0, N, chunk):
            c1 = min(c0 + chunk, N)
            items = stage1(_padded(Q[c0:c1], chunk))
            for b0 in range(c0, c1, block):
                # dispatch the next block before waiting for the last (JAX dispatches asynchronously):
                # the Python side of a call overlaps the previous block's computation
                H = stage2(items, np.int32(b0 - c0))
                if pending is not None:
                    finish(*pending)
                pending = (b0, min(b0 + block, c1), H)
            shown_bar.update(c1 - c0)
    finish(*pending)
    return out

__all__ = ["frf_sweep"]
