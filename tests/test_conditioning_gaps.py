"""Conditioning of stamps and angles on logs with real-log faults, made here by NumPy (no jflex
generator): stale rows (a logger writing its last sample again) are removed and interpolated from
the fresh neighbours; a gap short against the motion is bridged and reported, longer ones are
refused with every gap named; a log spliced from two runs (an angle jumping in one sample) is
refused naming the sample; equal stamps are named as such; the angles of a fine encoder whose
readings repeat, of a fast log of rounded readings, and of a log resampled from jittered stamps get
a cutoff near the motion's band, not tens of times above it."""

from __future__ import annotations

import numpy as np
import pytest

import jflex
from jflex.data import choose_cutoff, condition_torque, resample_uniform
from jflex.data._signal import angle_noise

JOINTS = ["a", "b"]


def _fourier(t, freqs, amp, seed):
    """(N, len(amp)) sums of sines at ``freqs`` [Hz] with random phases and weights 1/k."""
    rng = np.random.default_rng(seed)
    out = np.zeros((t.size, len(amp)))
    for j, a in enumerate(amp):
        c = rng.normal(size=len(freqs)) / np.arange(1, len(freqs) + 1)
        ph = rng.uniform(0, 2 * np.pi, len(freqs))
        out[:, j] = a * (np.sin(2 * np.pi * np.outer(t, freqs) + ph) @ c) / np.abs(c).sum()
    return out


def _log(n=4000, fs=1000.0, f0=0.5, seed=0):
    t = np.arange(n) / fs
    q = _fourier(t, [f0, 2 * f0, 3 * f0], [0.8, 0.5], seed)
    tau = 3.0 * np.sin(q) + 0.01 * np.random.default_rng(seed + 1).standard_normal(q.shape)
    return t, q, tau


def test_stale_rows_are_removed_and_interpolated_from_their_fresh_neighbours():
    t, q, tau = _log()
    # a robot at rest logged without noise from row 3000 to 3300 (a hold, not stale readings)
    k = np.arange(t.size)
    at = np.where(k < 3000, k, np.maximum(k - 300, 2999))
    qs, taus = q[at], tau[at]
    stale = np.array([500, 1200, 1201, 2500])  # one run of two
    for k in stale:
        qs[k], taus[k] = qs[k - 1], taus[k - 1]
    t2, out, rep, _ = condition_torque(t, {"q": qs, "tau": taus}, JOINTS, "log.csv")
    assert rep["sampling"]["repeated_rows"] == stale.size
    np.testing.assert_allclose(t2, t, atol=1e-12)
    # the stale samples are the straight line between the fresh samples around them
    for lo, hi in ((499, 501), (1199, 1202), (2499, 2501)):
        k = np.arange(lo + 1, hi)
        expect = qs[lo] + (qs[hi] - qs[lo]) * ((k - lo) / (hi - lo))[:, None]
        np.testing.assert_allclose(out["q"][k], expect, rtol=0, atol=1e-12)
        assert np.all(np.abs(out["q"][k] - qs[k]) > 0)
    np.testing.assert_allclose(out["q"][3000:3300], qs[3000:3300], rtol=0, atol=1e-12)
    fresh = np.setdiff1d(np.arange(t.size), stale)
    np.testing.assert_allclose(out["tau"][fresh], taus[fresh], rtol=0, atol=1e-12)


def test_a_short_gap_is_bridged_and_reported_and_long_ones_are_all_named():
    t, q, tau = _log(n=6000, f0=0.5)
    cut = np.r_[np.arange(0, 3001), np.arange(3009, 6000)]  # 8 samples lost: a 9 ms step
    t2, out, rep, _ = condition_torque(t[cut], {"q": q[cut], "tau": tau[cut]}, JOINTS, "log.csv")
    gaps = rep["sampling"]["gaps"]
    assert len(gaps) == 1 and gaps[0]["t_s"] == pytest.approx(3.0) and gaps[0]["length_s"] == pytest.approx(0.009)
    assert gaps[0]["action"].startswith("bridged")
    np.testing.assert_allclose(t2, t, atol=1e-9)
    k = np.arange(3001, 3009)
    expect = q[3000] + (q[3009] - q[3000]) * ((k - 3000) / 9.0)[:, None]
    np.testing.assert_allclose(out["q"][k], expect, atol=1e-9)
    # gaps of 0.3 s and 0.4 s in a 0.5-1.5 Hz motion: refused, both named
    cut = np.r_[np.arange(0, 2001), np.arange(2301, 4001), np.arange(4401, 6000)]
    with pytest.raises(jflex.DataError, match=r"a gap of 0\.301 s after t = 2 s.*a gap of 0\.401 s after t = 4 s"):
        condition_torque(t[cut], {"q": q[cut], "tau": tau[cut]}, JOINTS, "log.csv")
    # without angles to judge them by, any gap over 5 steps is refused, every one named
    with pytest.raises(jflex.DataError, match=r"a gap of 0\.009 s after t = 3 s.*no angles"):
        resample_uniform(t[np.r_[np.arange(0, 3001), np.arange(3009, 6000)]], {"x": np.zeros((5992, 1))}, "log.csv")


def test_a_spliced_log_is_refused_naming_the_sample_and_time():
    t = np.arange(3000) / 1000.0
    q = np.column_stack([0.005 * np.arange(3000), 0.2 * np.sin(2 * np.pi * t)])
    q[1700:, 0] += 1.27  # a second run appended: the angle jumps 1.27 rad in one sample
    tau = np.column_stack([np.cos(q[:, 0]), np.sin(q[:, 1])])
    with pytest.raises(jflex.DataError, match=r"joint a at sample 1700 \(t = 1\.7 s\): \+1\.275 rad"):
        condition_torque(t, {"q": q, "tau": tau}, JOINTS, "log.csv")
    q[1700:, 0] -= 1.27
    condition_torque(t, {"q": q, "tau": tau}, JOINTS, "log.csv")


def test_equal_stamps_are_named_as_such():
    t = np.full(50, 2.5)
    with pytest.raises(jflex.DataError, match=r"the stamps are all equal \(50 rows at 2\.5 s\)") as err:
        condition_torque(t, {"q": np.zeros((50, 2)), "tau": np.ones((50, 2))}, JOINTS, "log.csv")
    assert "nan" not in str(err.value)


def test_a_fine_encoder_whose_readings_repeat_gets_a_cutoff_near_the_motion():
    # 1-3 Hz motion at 1 kHz on a 2^17-count encoder, logged with jittered stamps and so resampled
    # (the readings are interpolated between repeated counts): the band the cutoff stands for (the
    # cutoff over its factor 2.5) keeps the motion's 3 Hz and stays within 3 x of it (the cutoff was
    # 288 Hz here)
    fs, step = 1000.0, 2 * np.pi / 2**17
    t = np.arange(10000) / fs
    rng = np.random.default_rng(5)
    tj = t + rng.uniform(-0.2, 0.2, t.size) / fs
    tj[0] = 0.0
    qj = np.round(_fourier(tj, [1.0, 2.0, 3.0], [0.02, 0.01, 0.005], 0) / step) * step
    t2, rows, rep = resample_uniform(tj, {"q": qj}, "log.csv")
    assert rep["resampled"]
    fc, info = choose_cutoff(rows["q"], float(np.mean(np.diff(t2))))
    assert 3.0 < fc / 2.5 <= 3 * 3.0, info
    # the same encoder read as it is, and written with 6 decimals (a CSV): the noise is the grid's
    qg = np.round(np.round(_fourier(t, [1.0, 2.0, 3.0], [0.5, 0.3, 0.2], 1) / step) * step + 1.3, 6)
    assert np.all(angle_noise(qg) >= 0.97 * step / np.sqrt(12)), angle_noise(qg)
    fc, info = choose_cutoff(qg, 1 / fs)
    assert info["method"] == "motion_band" and 3.0 < fc / 2.5 <= 3 * 3.0, info


def test_five_significant_digits_after_a_rest_are_no_splice():
    """A log that keeps 5 significant digits of a motor angle near 100 rad (a count of 0.01 rad
    there, 1e-4 near 1 rad) rests, then moves: its first count after the rest is no splice."""
    from jflex.data._condition import angle_jumps

    t = np.arange(20000) / 5000.0
    move = np.where(t < 1.0, 0.0, 0.3 * (1 - np.cos(2 * np.pi * 0.5 * (t - 1.0))))
    q = np.stack([100.48 + move, 1.2 + 0.1 * move], axis=1)
    q5 = np.array([[float(f"{v:.5g}") for v in row] for row in q])
    angle_jumps(t, q5, "log")  # no DataError
    spliced = q5.copy()
    spliced[12000:, 1] += 1.27
    with pytest.raises(jflex.JFlexError, match="jumps in one sample"):
        angle_jumps(t, spliced, "log")


def test_a_fast_log_of_rounded_readings_gets_a_cutoff_near_the_motion():
    # a 5 kHz log keeping 5 significant digits of motor angles near 20-60 rad (gear 32): its readings
    # repeat. The band is held by the angles' power read in 0.5 Hz steps (1024-sample segments step
    # 4.9 Hz at 5 kHz, and a 3 Hz motion read 14.6 Hz): within 3 x the motion's 3 Hz
    fs = 5000.0
    t = np.arange(int(6.3 * fs)) / fs
    motor = 32.0 * _fourier(t, [0.5, 1.0, 2.0, 3.0], [0.05, 0.04, 0.03], 3) + np.array([60.0, -40.0, 20.0])
    q = np.array([[float(f"{v:.5g}") for v in row] for row in motor]) / 32.0
    fc, info = choose_cutoff(q, 1 / fs)
    assert info["method"] == "motion_band" and 3.0 < fc / 2.5 <= 3 * 3.0, info


def test_a_resampled_log_holds_its_band_by_the_angles_power():
    # angles resampled from jittered stamps are interpolated between counts and between stamps that
    # were off: their sample-to-sample noise estimate reads neither, and a trace of fast motion
    # (here a 30 Hz line holding under 1e-6 of the power) carried the band, and the cutoff, to it. The
    # band of a resampled log is held within 2 x where 99.9 % of the angles' power lies
    from jflex.data._signal import motion_band, power_band

    fs = 1000.0
    t = np.arange(4000) / fs
    q = _fourier(t, [0.5, 1.0, 2.0, 3.0], [0.5, 0.4], 4) + 2e-4 * np.sin(2 * np.pi * 30.0 * t)[:, None]
    assert motion_band(q, 1 / fs) >= 30.0
    edge = power_band(q, 1 / fs, resolution_hz=0.5)
    assert 3.0 <= edge <= 4.0 and 3.0 < motion_band(q, 1 / fs, resampled=True) <= 2 * edge
    fc, info = choose_cutoff(q, 1 / fs, resampled=True)
    assert info["method"] == "motion_band" and fc / 2.5 <= 3 * 3.0, info
