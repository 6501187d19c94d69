"""Modal Assurance Criterion (seed 003 Eq. 4.14) and mode tracking across postures."""

from __future__ import annotations

import itertools

import jax
import jax.numpy as jnp


def mac(A, B=None, weight=None):
    """MAC matrix between the columns of ``A`` (n, ma) and ``B`` (n, mb) (default ``A``):

    $$ MAC_{rs} = |a_r^H W b_s|^2 / ((a_r^H W a_r)(b_s^H W b_s)) $$

    with ``W = weight`` (n, n) (e.g. the mass matrix, for which distinct modes give exactly 0)
    or the identity (Eq. 4.14). Complex shapes are allowed. **Returns:** (ma, mb) in [0, 1].
    """
    A = jnp.asarray(A)
    B = A if B is None else jnp.asarray(B)
    if A.ndim == 1:
        A = A[:, None]
    if B.ndim == 1:
        B = B[:, None]
    WB = B if weight is None else jnp.asarray(weight) @ B
    WA = A if weight is None else jnp.asarray(weight) @ A
    cross = jnp.conj(A).T @ WB
    na = jnp.real(jnp.einsum("ir,ir->r", jnp.conj(A), WA))
    nb = jnp.real(jnp.einsum("ir,ir->r", jnp.conj(B), WB))
    return jnp.abs(cross) ** 2 / (na[:, None] * nb[None, :])


def best_permutation(S):
    """Permutation ``p`` (m,) maximising ``sum_r S[r, p[r]]`` for a score matrix S (m, m):
    exhaustive for m <= 6, greedy (largest entries first) beyond."""
    m = S.shape[0]
    if m <= 6:
        perms = jnp.array(list(itertools.permutations(range(m))), dtype=int)
        scores = S[jnp.arange(m)[None, :], perms].sum(axis=1)
        return perms[jnp.argmax(scores)]

    def body(carry, _):
        p, S_ = carry
        k = jnp.argmax(S_)
        r, c = k // m, k % m
        return (p.at[r].set(c), S_.at[r, :].set(-jnp.inf).at[:, c].set(-jnp.inf)), None

    (p, _), _ = jax.lax.scan(body, (jnp.zeros(m, int), S), None, length=m)
    return p


def track_modes(shapes, *, weight=None):
    """Order modes along a path of postures so that mode r is the same physical mode everywhere.

    **Arguments:** ``shapes`` (T, n, m): the mode shapes at T postures along a path (neighbours
    close), in any order at each posture; ``weight`` optional (n, n) or (T, n, n) MAC weight.

    **Returns:** ``perm`` (T, m) int with ``shapes[t][:, perm[t]]`` consistently ordered (the
    first posture keeps its order), and ``continuity`` (T, m): the MAC of each tracked mode
    with itself at the previous posture (1 at t = 0; a low value flags a jump in the path).
    Use ``modes.reorder(perm[t])`` to reorder a :class:`Modes`.
    """
    shapes = jnp.asarray(shapes)
    T, n, m = shapes.shape
    W = None if weight is None else jnp.broadcast_to(jnp.asarray(weight), (T, n, n))

    def step(prev, inp):
        cur, w = inp
        S = mac(prev, cur, w)  # (m prev, m cur)
        p = best_permutation(S)
        return cur[:, p], (p, S[jnp.arange(m), p])

    ws = W[1:] if W is not None else None
    xs = (shapes[1:], ws) if ws is not None else (shapes[1:], None)
    if ws is None:
        _, (perms, cont) = jax.lax.scan(lambda c, s: step(c, (s, None)), shapes[0], shapes[1:])
    else:
        _, (perms, cont) = jax.lax.scan(step, shapes[0], xs)
    first = jnp.arange(m)[None, :]
    return jnp.concatenate([first, perms]), jnp.concatenate([jnp.ones((1, m)), cont])


def serpentine(n_rows: int, n_cols: int):
    """Flat indices of an (n_rows, n_cols) grid in boustrophedon order: a path through a posture
    grid whose consecutive points are neighbours, for :func:`track_modes` over a map."""
    import numpy as np

    idx = np.arange(n_rows * n_cols).reshape(n_rows, n_cols)
    idx[1::2] = idx[1::2, ::-1]
    return idx.ravel()
