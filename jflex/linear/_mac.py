"""Modal Assurance Criterion (the thesis "Posture Dependent Dynamics in Robotic Machining" Eq. 4.14), mode pairing and mode tracking across postures.

Pairing modes (:func:`pair_modes`): reference modes (measured, or the model's own at a reference
posture) are assigned one-to-one to model modes by a linear assignment (Hungarian algorithm,
``scipy.optimize.linear_sum_assignment``) on the cost

$$ c_{rs} = (1 - MAC_{rs}) + w_f |f_s - f_r| / f_r, $$

shape first, frequency as the tie-break (``w_f = 0.1`` by default: a 10 % frequency distance
weighs like 0.01 of MAC). Pairing by MAC alone goes wrong where two modes come close in frequency
and their shapes mix (both rows of the MAC matrix near 0.5): the assignment then follows the
frequencies. Pairing by frequency alone goes wrong where close modes trade places in frequency
order while keeping their shapes (the Kuka KR90's modes 1 and 2 between its configurations 1 and
2), which MAC against the reference shapes follows. Tracking a path of postures step by step
(:func:`track_modes`) is a different question, "which mode continues into which", and can follow
a veering pair onto the other branch; the thesis' tables label rows by shape likeness to
configuration 1, which :func:`pair_modes` against configuration 1's shapes reproduces.
"""

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


def pair_modes(ref_shapes, shapes, ref_frequency=None, frequency=None, *, weight=None, frequency_weight: float = 0.1):
    """Pair each reference mode with one model mode: linear assignment on ``(1 - MAC) + w_f x``
    relative frequency distance (module docstring).

    **Arguments:** ``ref_shapes`` (n, m_ref) and ``shapes`` (n, m) with ``m >= m_ref`` (real or
    complex columns); ``ref_frequency`` (m_ref,) and ``frequency`` (m,) [Hz], optional (without
    them the pairing is by MAC alone); ``weight`` optional (n, n) MAC weight;
    ``frequency_weight`` ``w_f`` >= 0.

    **Returns:** ``index`` (m_ref,) int, the model mode paired with each reference mode, and
    ``mac_paired`` (m_ref,), the MAC of each pair (a low value flags a pair that shapes do not
    support). NumPy (outside jit): the assignment is combinatorial.
    """
    import numpy as np
    from scipy.optimize import linear_sum_assignment

    from .._errors import ShapeError

    S = np.asarray(mac(ref_shapes, shapes, weight))
    m_ref, m = S.shape
    if m < m_ref:
        raise ShapeError(f"pair_modes: {m_ref} reference modes but only {m} model modes to pair them with")
    if frequency_weight < 0:
        raise ValueError(f"pair_modes: frequency_weight must be >= 0, got {frequency_weight}")
    cost = 1.0 - np.nan_to_num(S, nan=0.0)
    if ref_frequency is not None and frequency is not None:
        fr = np.asarray(ref_frequency, dtype=float)
        f = np.asarray(frequency, dtype=float)
        if fr.shape != (m_ref,) or f.shape != (m,):
            raise ShapeError(f"pair_modes: frequencies of shape {fr.shape} and {f.shape} for {m_ref} and {m} modes")
        d = np.abs(f[None, :] - fr[:, None]) / np.abs(fr[:, None])
        cost = cost + frequency_weight * np.where(np.isfinite(d), d, 1e6)
    rows, cols = linear_sum_assignment(cost)
    index = np.empty(m_ref, dtype=int)
    index[rows] = cols
    return index, S[np.arange(m_ref), index]


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
