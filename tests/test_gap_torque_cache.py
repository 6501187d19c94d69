"""A filtered torque set keeps one copy of each term's columns: the unfiltered ones a term made (its
own or a block shared with others), the raw regressor and the columns of hyper-parameters a search
left are dropped, and the normal equations still equal the products over every sample written out
here with SciPy's Butterworth filter; what is made again equals what was dropped, bit for bit."""

import dataclasses

import numpy as np
import pytest
from scipy.signal import butter, sosfiltfilt

import jflex.gap.torque._set as T
from jflex.data._signal import BUTTER_ORDER

RATE, CUTOFF = 100.0, 5.0


def _lp(x):
    """The parallel filter written out: zero-phase Butterworth at CUTOFF along axis 0."""
    sos = butter(BUTTER_ORDER, CUTOFF / (0.5 * RATE), output="sos")
    return sosfiltfilt(sos, x, axis=0, padtype="odd", padlen=min(3 * (2 * BUTTER_ORDER + 1) * 4, x.shape[0] - 1))


@dataclasses.dataclass(frozen=True)
class _Term:
    """Columns (N, n, k) cut from a random block (N, n, 3k) that several terms share, each kept in
    the set's cache as the library's kinds keep theirs: the block, and the term's own slice."""

    seed: int
    k: int
    hyper: float = 1.0

    @property
    def n_params(self):
        return self.k

    def _block(self, s):
        return np.random.default_rng(self.seed).normal(size=s.q.shape + (3 * self.k,)) * self.hyper

    def columns(self, s):
        block = s.cache.setdefault(("block", self.seed, self.hyper), self._block(s))
        s.cache[("own", self.seed, self.hyper)] = np.ascontiguousarray(block[:, :, :self.k])
        return s.cache[("own", self.seed, self.hyper)]

    def bounds(self):
        return np.full(self.k, -np.inf), np.full(self.k, np.inf)

    def search(self, base_terms, base_delay, sets, inertia=None):
        fits = [T.fit_terms(tuple(base_terms) + (dataclasses.replace(self, hyper=h),), base_delay, sets, inertia)
                for h in (0.5, 1.0, 2.0)]
        return min(fits, key=lambda f: f.cost)


class _Prior:
    def __init__(self, size):
        self.size = size

    def bounds(self):
        return np.full(self.size, -np.inf), np.full(self.size, np.inf)

    def penalty(self):
        return np.full(self.size, 1e-3)


def _set(N=400, n=2, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(N) / RATE
    z = lambda *shape: rng.normal(size=shape)  # noqa: E731
    return T.TorqueSet("s", t, z(N, n), z(N, n), z(N, n), z(N, n), z(N, n), np.abs(z(n)) + 0.5,
                       z(N, n, 10 * n), np.zeros((N, 0)), (), cutoff=CUTOFF)


def test_one_copy_of_each_column_and_the_same_normal_equations():
    s = _set()
    Y0 = s.Y.copy()
    a, b = _Term(1, 2), _Term(2, 1)
    G, g, yy, _ = T._gram((a, b), 0.0, s, _Prior(Y0.shape[2]))
    # the unfiltered columns (the terms' own and the blocks they share) are gone, the filtered stay
    assert not any(k[0] in ("own", "block") for k in s.cache if isinstance(k, tuple))
    assert {("cols", a), ("cols", b)} <= set(s.cache)
    # the raw regressor is replaced by its filtered copy, which is never filtered again
    np.testing.assert_allclose(s.Y, _lp(Y0.reshape(len(s.t), -1)).reshape(Y0.shape), rtol=1e-12, atol=1e-12)
    twin = dataclasses.replace(s, cache={})
    assert T._filtered(twin, "Y") is s.Y and T._filtered(s, "Y") is s.Y
    # the normal equations against the products over every sample with SciPy's filter
    w = 1.0 / s.scale
    cols = [_lp(t._block(s)[:, :, :t.k]) for t in (a, b)]
    A = np.concatenate([_lp(Y0.reshape(len(s.t), -1)).reshape(Y0.shape)] + cols, axis=2) * w[None, :, None]
    A = A.reshape(s.tau.size, -1)
    y = ((s.tau - _lp(s.F0)) * w[None, :]).ravel()
    np.testing.assert_allclose(G, A.T @ A, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(g, A.T @ y, rtol=1e-10, atol=1e-10)
    assert yy == pytest.approx(float(y @ y), rel=1e-12)


def test_a_search_keeps_the_columns_of_its_choice_only_and_repeats_exactly():
    s = _set(seed=3)
    base = (_Term(5, 1),)
    first = T.fit_with(base, 0.0, _Term(7, 2), [s])
    chosen = first.terms[-1]
    left = {k[1] for k in s.cache if isinstance(k, tuple) and k[0] == "cols"}
    assert left == {base[0], chosen}
    # the products of the terms tried stay; their columns are made again when needed, the same
    again = T.fit_with(base, 0.0, _Term(7, 2), [s])
    assert again.terms == first.terms
    assert np.array_equal(again.theta, first.theta) and again.cost == first.cost
    fresh = T.fit_with(base, 0.0, _Term(7, 2), [_set(seed=3)])
    assert np.array_equal(fresh.theta, first.theta)
