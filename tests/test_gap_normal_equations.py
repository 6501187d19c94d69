"""The torque fits' normal equations, assembled from per-term blocks kept with each data set, equal
the products written out over every sample (NumPy, in this file), whatever the order of the
terms, the delay, and whether the blocks come from the set's cache or are made afresh."""

import dataclasses

import numpy as np
import pytest

import jflex.gap.torque._set as T


@dataclasses.dataclass(frozen=True)
class _Term:
    """A term whose columns are fixed random arrays (N, n, k)."""

    seed: int
    k: int

    @property
    def n_params(self):
        return self.k

    def columns(self, s):
        return np.random.default_rng(self.seed).normal(size=s.q.shape + (self.k,))

    def bounds(self):
        return np.full(self.k, -np.inf), np.full(self.k, np.inf)


class _Prior:
    """The inertial part's size, bounds and penalty (a stand-in for the CAD prior)."""

    def __init__(self, size):
        self.size = size

    def bounds(self):
        return np.full(self.size, -np.inf), np.full(self.size, np.inf)

    def penalty(self):
        return np.full(self.size, 1e-3)


def _set(N=300, n=3, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(N) * 0.01
    z = lambda *shape: rng.normal(size=shape)  # noqa: E731
    return T.TorqueSet("s", t, z(N, n), z(N, n), z(N, n), z(N, n), z(N, n), np.abs(z(n)) + 0.5,
                       z(N, n, 10 * n), np.zeros((N, 0)), ())


def _direct(terms, delay, s, inertia):
    w = 1.0 / s.scale
    A = np.concatenate([t.columns(s) for t in terms], axis=2) * w[None, :, None]
    A = A.reshape(s.tau.size, -1)
    y = ((T.shift(s.tau, s.t, -delay) - s.F0) * w[None, :]).ravel()
    if inertia:
        A = np.concatenate([(s.Y * w[None, :, None]).reshape(s.tau.size, -1), A], axis=1)
    return A.T @ A, A.T @ y, float(y @ y)


@pytest.mark.parametrize("inertia", [False, True])
def test_blocks_equal_the_products_over_every_sample(inertia):
    s = _set()
    a, b, c = _Term(1, 2), _Term(2, 1), _Term(3, 3)
    prior = _Prior(10 * s.q.shape[1]) if inertia else None
    # the same terms in other orders and at other delays, once with an empty cache, then from it
    for terms, delay in [((a, b), 0.0), ((b, a), 0.0), ((a, b, c), 0.013), ((c, a), 0.013), ((a,), -0.02),
                         ((a, b), 0.0), ((c, b, a), 0.013)]:
        G, g, yy, rows = T._gram(terms, delay, s, prior)
        G0, g0, yy0 = _direct(terms, delay, s, inertia)
        np.testing.assert_allclose(G, G0, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(g, g0, rtol=1e-12, atol=1e-9)
        assert yy == pytest.approx(yy0, rel=1e-12) and rows == s.tau.size


def test_fit_equals_least_squares_on_the_stacked_rows():
    s = _set(seed=4)
    a, b = _Term(5, 2), _Term(6, 2)
    for terms in [(a, b), (b, a), (a, b)]:
        fit = T.fit_terms(terms, 0.0, [s])
        G0, g0, _ = _direct(terms, 0.0, s, False)
        np.testing.assert_allclose(fit.theta, np.linalg.solve(G0, g0), rtol=1e-8)
