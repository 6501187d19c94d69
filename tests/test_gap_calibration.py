"""The diagnosis' statements carry a false-alarm rate: "beyond the floor" is a test at one
family-wise level over every joint and set (F quantiles on the noise's effective samples, a
Bonferroni correction), checked here by Monte Carlo on coloured noise made with NumPy; a joint
may not be made worse by more than its own gap's uncertainty; a payload is a rigid body."""

import numpy as np
import pytest
from scipy.stats import f as fdist

from jflex.gap import FAMILY_ALPHA, SIGNIFICANCE, gap_uncertainty, significance_factor, worse_channels
from jflex.gap.judge._periodic import effective_samples
from jflex.gap.judge._selection import DOF_SHARE, _beyond
from jflex.gap.torque._terms import nearest_rigid_body, payload_implausible


def test_significance_factor_is_the_corrected_F_quantile():
    for dof, tests in ((8.0, 1), (30.0, 14), (60.0, 40)):
        q = fdist.ppf(1 - FAMILY_ALPHA / tests, DOF_SHARE * dof, DOF_SHARE * dof)
        assert significance_factor(dof, tests) == pytest.approx(max(SIGNIFICANCE, np.sqrt(q)))
    # more tests, or fewer effective samples, need a larger margin; a floor of no samples none
    assert significance_factor(30.0, 20) > significance_factor(30.0, 1)
    assert significance_factor(10.0, 5) > significance_factor(100.0, 5)
    assert significance_factor(0.5, 3) == np.inf
    assert significance_factor(1.5, 3) < np.inf
    assert significance_factor(1e6, 50) == SIGNIFICANCE


def _ar1(rng, n, pole, shape):
    e = rng.standard_normal((n,) + shape)
    x = np.empty_like(e)
    x[0] = e[0] / np.sqrt(1 - pole**2)
    for k in range(1, n):
        x[k] = pole * x[k - 1] + e[k]
    return x


def test_family_wise_false_alarm_rate_on_coloured_noise():
    """Seven joints, each a gap and a floor measured on two records of the same AR(1) noise (pole
    0.97: ~N/65 effective samples): with the margin of ``significance_factor`` at the noise's
    measured effective samples, some joint is called beyond its floor in at most FAMILY_ALPHA of the
    trials (plus Monte Carlo slack); a per-joint margin that counts rows as samples, or that ignores
    the number of joints, alarms far more often."""
    rng = np.random.default_rng(1)
    joints, N, trials, pole = 7, 1500, 300, 0.97
    alarms_cal = alarms_rows = alarms_one = 0
    for _ in range(trials):
        a, b = _ar1(rng, N, pole, (joints,)), _ar1(rng, N, pole, (joints,))
        gap, floor = np.sqrt(np.mean(a**2, axis=0)), np.sqrt(np.mean(b**2, axis=0))
        dof = np.array([effective_samples(b[:, j]) for j in range(joints)])
        # (the margin alone: floors of ~1, far above MIN_GAP's 0.2 % are scaled away)
        g, fl = 100 * gap, 100 * floor
        alarms_cal += any(g[j] > significance_factor(dof[j], joints) * fl[j] for j in range(joints))
        alarms_rows += any(g[j] > np.sqrt(fdist.ppf(1 - FAMILY_ALPHA / joints, N, N)) * fl[j] for j in range(joints))
        alarms_one += any(g[j] > np.sqrt(fdist.ppf(1 - FAMILY_ALPHA, dof[j], dof[j])) * fl[j] for j in range(joints))
    rate = alarms_cal / trials
    assert rate <= FAMILY_ALPHA + 2.5 * np.sqrt(FAMILY_ALPHA * (1 - FAMILY_ALPHA) / trials)
    assert alarms_rows / trials > 3 * FAMILY_ALPHA
    assert alarms_one / trials > rate


def test_beyond_uses_the_channel_margin():
    assert _beyond(1.5, 1.0)  # 1.2 x 1.0 + 0.2 = 1.4
    assert not _beyond(1.5, 1.0, significance_factor(20.0, 10))


def test_a_joint_made_worse_beyond_its_own_gaps_uncertainty_is_vetoed():
    """The withheld real log: a payload fit took joint 5 from 15.6 % to 29.3 % with a floor of
    14.6 % there; within the floor it passed, against the uncertainty of its own gap it does not."""
    ev0 = {"v": {"kind": "torque", "channels": {"j5": 15.6, "j1": 3.0}}}
    ev1 = {"v": {"kind": "torque", "channels": {"j5": 29.3, "j1": 3.01}}}
    cf = {"v": {"j5": 14.6, "j1": 2.9}}
    assert worse_channels(ev1, ev0, cf) == []
    rel = {"v": {"j5": gap_uncertainty(200.0), "j1": gap_uncertainty(200.0)}}
    w = worse_channels(ev1, ev0, cf, rel)
    assert [x["channel"] for x in w] == ["j5"]
    assert w[0]["floor"] == pytest.approx(15.6 * 3 / np.sqrt(400))
    # the uncertainty of a gap measured on few effective samples is large: no veto
    assert worse_channels(ev1, ev0, cf, {"v": {"j5": gap_uncertainty(2.0)}}) == []


def _sphere(m, c, r):
    c = np.asarray(c, float)
    I = 0.4 * m * r**2 * np.eye(3) + m * (c @ c * np.eye(3) - np.outer(c, c))
    return np.array([m, *(m * c), I[0, 0], I[0, 1], I[1, 1], I[0, 2], I[1, 2], I[2, 2]])


def test_payload_plausibility_is_the_pseudo_inertia():
    assert payload_implausible(_sphere(2.0, [0.1, 0.0, 0.05], 0.04)) is None
    # a point mass (a singular pseudo-inertia) is a body
    assert payload_implausible(_sphere(1.0, [0.0, 0.2, 0.0], 0.0)) is None
    # the withheld real log's fit: no mass, a negative first moment and negative moments of inertia
    assert "positive mass" in payload_implausible([0.0, -0.02, 0.0, 0.0, -0.003, 0.0, -0.002, 0.0, 0.0, -0.004])
    bad = _sphere(2.0, [0.1, 0.0, 0.05], 0.04)
    bad[4] -= 0.05  # Ixx below what the other moments allow (a triangle inequality broken)
    assert "negative eigenvalue" in payload_implausible(bad)


def test_nearest_rigid_body_is_a_body_and_locally_nearest():
    rng = np.random.default_rng(3)
    A = rng.standard_normal((10, 10))
    S = A @ A.T + 0.1 * np.eye(10)
    theta = _sphere(1.5, [0.05, -0.02, 0.08], 0.05)
    theta[[4, 6, 9]] -= 0.02  # non-physical
    assert payload_implausible(theta) is not None
    p = nearest_rigid_body(theta, S)
    assert payload_implausible(p) is None

    def cost(x):
        return float((x - theta) @ S @ (x - theta))

    # no body in a neighbourhood of it is nearer (bodies drawn by perturbing its pseudo-inertia's
    # Cholesky factor, which covers every body)
    from jflex.identify._physical import pseudo_inertia, pseudo_inertia_to_params

    L = np.linalg.cholesky(pseudo_inertia(p) + 1e-12 * np.eye(4))
    for _ in range(300):
        Lk = L + 1e-3 * np.tril(rng.standard_normal((4, 4))) * np.abs(L).max()
        q = pseudo_inertia_to_params(Lk @ Lk.T, np)
        assert cost(q) >= cost(p) - 1e-9 * max(cost(p), 1e-12)
    # a body is left as it is
    assert nearest_rigid_body is not None and payload_implausible(_sphere(1.0, [0, 0, 0.1], 0.05)) is None


def test_velocity_lag_of_a_backward_difference_is_half_a_sample():
    """A drive that logs the backward difference of its encoder reads its velocity h/2 late; logged
    exactly (the derivative of the angle), no lag."""
    from jflex.data._signal import velocity_lag

    h = 1e-3
    t = np.arange(6000) * h
    q = np.stack([0.8 * np.sin(2 * np.pi * 0.7 * t) + 0.3 * np.sin(2 * np.pi * 1.9 * t + 0.4),
                  0.5 * np.cos(2 * np.pi * 1.1 * t)], axis=1)
    step = 2 * np.pi / 2**16
    qq = np.round(q / step) * step  # an encoder's counts
    back = np.vstack([np.zeros((1, 2)), np.diff(qq, axis=0) / h])
    exact = np.stack([0.8 * 2 * np.pi * 0.7 * np.cos(2 * np.pi * 0.7 * t)
                      + 0.3 * 2 * np.pi * 1.9 * np.cos(2 * np.pi * 1.9 * t + 0.4),
                      -0.5 * 2 * np.pi * 1.1 * np.sin(2 * np.pi * 1.1 * t)], axis=1)
    assert velocity_lag(qq, back, h, 10.0) == pytest.approx(h / 2, rel=0.05)
    assert abs(velocity_lag(q, exact, h, 10.0)) < 0.02 * h
