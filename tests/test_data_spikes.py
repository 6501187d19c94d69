"""Spikes in a log that rests for most of its length: the noise scale a spike is judged against is
local, so the ordinary noise of the moving part is not counted as spikes (made here by NumPy:
a smooth torque, white noise of two levels, planted single-sample outliers)."""

import numpy as np

from jflex.data import find_spikes


def test_spikes_in_a_mostly_resting_log_are_the_planted_ones():
    rng = np.random.default_rng(0)
    n, moving = 10000, slice(0, 3000)  # 30 % moving, then at rest
    t = np.arange(n) * 1e-3
    x = np.where(t < 3.0, 5.0 * np.sin(2 * np.pi * 0.7 * t), 0.0) + 1e-4 * rng.standard_normal(n)
    x[moving] += 0.05 * rng.standard_normal(3000)
    at = np.array([500, 1700, 2600, 5000, 8000])
    x[at[:3]] += 1.0  # 20 noise std of the moving part
    x[at[3:]] -= 0.01  # 100 noise std at rest
    found = find_spikes(x)
    assert set(found) == set(at)
    # the moving part alone, and the log without the planted outliers (the record-wide scale, the
    # rest's, flagged about a quarter of the moving samples here)
    assert set(find_spikes(x[moving])) == set(at[:3])
    clean = x.copy()
    clean[at[:3]] -= 1.0
    clean[at[3:]] += 0.01
    assert find_spikes(clean).size == 0
