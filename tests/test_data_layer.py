"""The data layer (jflex.data) on logs with real-log traits, made here by NumPy and Pinocchio: stamps
that jitter and drop samples give the arrays of their uniform twin; records at 250 Hz and 1 kHz
each get their own low-pass cutoff inside (0, 0.8 Nyquist); dead and flat torque channels are
named and left out; spikes are counted; several CSV files merge on time; motor currents become
joint torques through a coupling matrix as a hand computation says; a torque NPZ whose columns are
permuted loads in model order; a forgotten current constant is refused."""

from __future__ import annotations

import pathlib
import sys

import numpy as np
import pinocchio as pin
import pytest
import yaml

import jflex
from jflex.data import (channel_quality, choose_cutoff, condition_torque, currents_to_torque, find_spikes,
                        resample_uniform)
from jflex.gap import load_case

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "gap"))
from independent import robots as R  # noqa: E402
from independent import signals as S  # noqa: E402

JOINTS = ["joint1", "joint2", "joint3"]


def _motion(seed=0, f0=0.2):
    rng = np.random.default_rng(seed)
    return S.Fourier(rng, center=[0.0, 0.7, -1.3], amp=[0.8, 0.5, 0.6], f0=f0, harmonics=5)


def _pin_tau(traj, t):
    model = pin.buildModelFromXML(R.ARM3_URDF)
    data = model.createData()
    q, qd, qdd = traj(t, 0), traj(t, 1), traj(t, 2)
    return np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, qd, qdd)])


def _write_csv(path, t, cols: dict):
    names = ["time"] + list(cols)
    lines = [",".join(names)]
    for k in range(t.size):
        lines.append(",".join([f"{t[k]:.12g}"] + [f"{cols[c][k]:.12g}" for c in cols]))
    path.write_text("\n".join(lines) + "\n")


def _case(folder: pathlib.Path, datasets, robot="robot.urdf", options=None):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "robot.urdf").write_text(R.ARM3_URDF)
    cfg = {"robot": robot, "datasets": datasets}
    if options:
        cfg["options"] = options
    (folder / "case.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    return folder


def _torque_entry(file, split, tau_cols=None, **extra):
    cols = {"time": "time", "position": {j: f"q_{j}" for j in JOINTS},
            "torque": tau_cols or {j: f"tau_{j}" for j in JOINTS}}
    return {"kind": "torque", "file": file, "split": split, "columns": cols, **extra}


def _log_cols(traj, t, tau):
    q = traj(t, 0)
    return {**{f"q_{j}": q[:, k] for k, j in enumerate(JOINTS)}, **{f"tau_{j}": tau[:, k] for k, j in enumerate(JOINTS)}}


# --- stamps ----------------------------------------------------------------------------------------
def test_jitter_drops_and_repeats_resample_to_the_uniform_twin(tmp_path):
    traj, h, n = _motion(), 0.01, 1500
    rng = np.random.default_rng(1)
    t_u = h * np.arange(n)
    # +-20 % of a step of jitter, 12 isolated samples dropped, 5 rows logged twice
    t_j = t_u + rng.uniform(-0.2, 0.2, n) * h
    t_j[0] = 0.0
    drop = np.sort(rng.choice(np.arange(10, n - 10, 3), 12, replace=False))
    t_j = np.delete(t_j, drop)
    rep = np.sort(rng.choice(np.arange(10, t_j.size - 10), 5, replace=False))
    t_j = np.insert(t_j, rep + 1, t_j[rep])
    for name, t in (("uniform", t_u), ("jitter", t_j)):
        _write_csv(tmp_path / f"{name}.csv", t, _log_cols(traj, t, _pin_tau(traj, t)))
    twin = load_case(_case(tmp_path / "u", [_torque_entry("../uniform.csv", "train"),
                                             _torque_entry("../uniform.csv", "validation", name="v")]),
                     allow_outside=True).datasets[0]
    jit = load_case(_case(tmp_path / "j", [_torque_entry("../jitter.csv", "train"),
                                            _torque_entry("../uniform.csv", "validation", name="v")]),
                    allow_outside=True).datasets[0]
    s = jit.conditioning["sampling"]
    assert s["resampled"] and s["dropped_samples"] == 12 and s["repeated_stamps"] == 5 and s["jitter_pct"] > 20
    # the jitter is that of the steps that dropped nothing (stamps +-20 %: steps within +-40 %, the
    # median step a little off h); a step over one dropped sample is about two steps long
    assert s["jitter_pct"] < 42
    assert 1.55 < s["longest_step"] < 2.45
    assert not twin.conditioning["sampling"]["resampled"]
    # on its grid the resampled log is the motion within linear interpolation's error h^2/8 |q''|
    t = jit.arrays["t"]
    assert abs(np.diff(t).std()) < 1e-9 and abs(np.mean(np.diff(t)) - h) < 0.01 * h
    step = np.diff(np.unique(t_j)).max()  # the longest step bridged (a dropped sample's, jittered)
    bound = step**2 / 8 * np.abs(traj(t, 2)).max(axis=0)
    err = np.abs(jit.arrays["q"] - traj(t, 0)).max(axis=0)
    assert np.all(err < bound), (err, bound)
    # the twin's q is the motion to the CSV's 12 digits; torques agree with the twin interpolated
    np.testing.assert_allclose(twin.arrays["q"], traj(twin.arrays["t"], 0), atol=1e-10)
    tau_twin = np.column_stack([np.interp(t, twin.arrays["t"], twin.arrays["tau"][:, k]) for k in range(3)])
    scale = np.abs(twin.arrays["tau"]).max(axis=0)
    assert np.all(np.abs(jit.arrays["tau"] - tau_twin).max(axis=0) < 0.01 * scale)
    # and the diagnosis' input: each record's cutoff from its spectrum agrees within 10 %
    fc_u, _ = choose_cutoff(twin.arrays["q"], h)
    fc_j, _ = choose_cutoff(jit.arrays["q"], float(np.mean(np.diff(t))))
    assert abs(fc_j / fc_u - 1) < 0.1, (fc_u, fc_j)


def test_a_step_back_in_time_and_a_long_gap_are_refused():
    t = np.arange(100) * 0.01
    t[50] = t[48]
    with pytest.raises(jflex.DataError, match=r"field 't': time goes back at sample 50"):
        condition_torque(t, {"q": np.zeros((100, 1)), "tau": np.ones((100, 1))}, ["j"], "log.csv")
    t = np.r_[np.arange(50), np.arange(60, 110)] * 0.01
    with pytest.raises(jflex.DataError, match=r"a gap of 0\.1\d* s"):
        resample_uniform(t + np.random.default_rng(0).uniform(-2e-3, 2e-3, t.size), {"x": t[:, None]}, "log.csv")


# --- cutoff per record -----------------------------------------------------------------------------
@pytest.mark.parametrize("noise", [0.0, 2e-5])
def test_records_at_250_hz_and_1_khz_each_get_their_own_cutoff(tmp_path, noise):
    traj = _motion(2, f0=0.5)
    rng = np.random.default_rng(3)
    for name, fs, T in (("slow", 250.0, 6.0), ("fast", 1000.0, 3.0)):
        t = np.arange(int(T * fs)) / fs
        cols = _log_cols(traj, t, _pin_tau(traj, t))
        for j in JOINTS:
            cols[f"q_{j}"] = cols[f"q_{j}"] + noise * rng.standard_normal(t.size)
        _write_csv(tmp_path / f"{name}.csv", t, cols)
    case = load_case(_case(tmp_path, [_torque_entry("slow.csv", "train"), _torque_entry("fast.csv", "validation")]))
    from jflex.gap.torque._set import torque_set

    cut = {}
    for d in case.datasets:
        fs = 1.0 / float(np.mean(np.diff(d.arrays["t"])))
        s = torque_set(case.robot, d)
        cut[d.name] = s.cutoff
        assert 0 < s.cutoff < 0.8 * fs / 2, (d.name, s.processing["cutoff"])
        assert s.processing["cutoff"]["nyquist_hz"] == pytest.approx(fs / 2)
        assert s.processing["cutoff_method"] in ("motion_band", "spectrum_floor", "energy", "limit")
        # the motion's harmonics reach 2.5 Hz: the filter keeps them
        assert s.cutoff > 2.5
    assert set(cut) == {"slow", "fast"}


def test_cutoff_fallback_is_named_and_inside_the_limit():
    # noise-free angles at 100 Hz: nothing stands above a noise floor; the choice stays below 40 Hz
    t = np.arange(4000) / 100.0
    q = _motion(4)(t, 0)
    fc, info = choose_cutoff(q, 0.01)
    assert 0 < fc < 0.8 * 50 and info["method"] in ("motion_band", "spectrum_floor", "energy", "limit")
    # white noise only: whatever the spectrum says, inside the limit and named
    fc, info = choose_cutoff(np.random.default_rng(0).standard_normal((4000, 2)), 0.01)
    assert 0 < fc < 40 and info["method"] in ("motion_band", "spectrum_floor", "energy", "limit")
    # a record at 1 kHz of a fast, noise-free motion: its cutoff follows its own Nyquist frequency
    t = np.arange(8000) / 1000.0
    fc_fast, _ = choose_cutoff(_motion(4, f0=2.0)(t, 0), 1e-3)
    assert 0 < fc_fast < 400


def test_velocities_without_accelerations_are_filtered_before_differentiation(tmp_path):
    traj, fs = _motion(5), 500.0
    t = np.arange(int(10 * fs)) / fs
    rng = np.random.default_rng(6)
    cols = _log_cols(traj, t, _pin_tau(traj, t))
    qd = traj(t, 1) + 2e-3 * rng.standard_normal((t.size, 3))
    cols.update({f"qd_{j}": qd[:, k] for k, j in enumerate(JOINTS)})
    _write_csv(tmp_path / "log.csv", t, cols)
    vel = {j: f"qd_{j}" for j in JOINTS}
    train = _torque_entry("log.csv", "train")
    train["columns"]["velocity"] = vel
    case = load_case(_case(tmp_path, [train, _torque_entry("log.csv", "validation", name="v")]))
    d = case.datasets[0]
    assert d.conditioning["derivatives"] == "velocity"
    from jflex.gap.torque._set import torque_set

    s = torque_set(case.robot, d)
    true = traj(s.t, 2)
    raw = np.gradient(qd, t, axis=0)  # what differentiating the given rates unfiltered gives
    err_f = np.sqrt(np.mean((s.qdd - true) ** 2))
    err_raw = np.sqrt(np.mean((raw - traj(t, 2)) ** 2))
    assert err_f < 0.05 * err_raw, (err_f, err_raw)
    assert "velocities filtered" in s.processing["derivatives"]


# --- channels --------------------------------------------------------------------------------------
def test_dead_and_flat_channels_are_named_and_left_out(tmp_path):
    traj = _motion(7)
    t = np.arange(2000) * 0.005
    tau = _pin_tau(traj, t) + 0.01 * np.random.default_rng(8).standard_normal((t.size, 3))
    tau_dead = tau.copy()
    off = np.random.default_rng(9).random(t.size) < 0.86  # a sensor off 86 % of the time
    tau_dead[off, 2] = 0.0
    tau_dead[:, 1] = 0.013  # a channel stuck at a constant reading
    _write_csv(tmp_path / "bad.csv", t, _log_cols(traj, t, tau_dead))
    _write_csv(tmp_path / "good.csv", t, _log_cols(traj, t, tau))
    entries = [_torque_entry("../bad.csv", "train"), _torque_entry("../good.csv", "validation")]
    case = load_case(_case(tmp_path / "c", entries), allow_outside=True)
    bad, good = case.datasets
    assert bad.excluded_channels == ("joint2", "joint3") and good.excluded_channels == ()
    assert case.excluded_channels == ("joint2", "joint3")
    ch = bad.conditioning["channels"]
    assert "dead" in ch["joint3"]["flags"] and ch["joint3"]["zero_fraction"] > 0.8
    assert "flat" in ch["joint2"]["flags"] and ch["joint1"]["flags"] == []
    assert "dead" in bad.channels["tau:joint3"].flags and bad.channels["tau:joint3"].source.endswith(":tau_joint3")
    # the user keeps one: it stays in, its flags still reported
    kept = load_case(_case(tmp_path / "k", entries, options={"keep_channels": ["joint3"]}),
                     allow_outside=True).datasets[0]
    assert kept.excluded_channels == ("joint2",) and kept.conditioning["channels"]["joint3"]["kept_by_user"]


def test_channel_quality_flags_each_trait():
    rng = np.random.default_rng(10)
    x = np.sin(np.linspace(0, 20, 4000)) + 0.01 * rng.standard_normal(4000)
    assert channel_quality(x)["flags"] == []
    assert "saturated" in channel_quality(np.clip(x, -0.8, 0.8))["flags"]
    assert "few_levels" in channel_quality(np.round(x * 2) / 2)["flags"]
    stuck = x.copy()
    stuck[1000:2200] = stuck[1000]
    assert "stuck" in channel_quality(stuck)["flags"]
    # the same hold while the robot rests (a noise-free torque at rest) is no fault
    moving = np.ones(4000, bool)
    moving[1000:2200] = False
    assert "stuck" not in channel_quality(stuck, moving=moving)["flags"]
    assert "flat" in channel_quality(1e-7 * x, fellow_std=1.0)["flags"]


def test_spikes_are_counted_and_replaced_only_when_asked(tmp_path):
    traj = _motion(11)
    t = np.arange(3000) * 0.004
    tau = _pin_tau(traj, t) + 0.01 * np.random.default_rng(12).standard_normal((t.size, 3))
    spiky = tau.copy()
    at = np.array([400, 1200, 2500])
    spiky[at, 0] += 30.0
    assert set(find_spikes(spiky[:, 0])) == set(at)
    assert find_spikes(tau[:, 0]).size == 0
    _write_csv(tmp_path / "s.csv", t, _log_cols(traj, t, spiky))
    entries = [_torque_entry("s.csv", "train"), _torque_entry("s.csv", "validation", name="v")]
    d = load_case(_case(tmp_path / "a", [dict(e, file="../s.csv") for e in entries]), allow_outside=True).datasets[0]
    assert d.conditioning["spikes"]["joint1"]["count"] == 3 and d.conditioning["spikes"]["joint1"]["action"] == "flagged"
    assert d.arrays["tau"][at[0], 0] == pytest.approx(spiky[at[0], 0])
    d = load_case(_case(tmp_path / "b", [dict(e, file="../s.csv") for e in entries],
                        options={"replace_spikes": True}), allow_outside=True).datasets[0]
    assert np.abs(d.arrays["tau"][at, 0] - tau[at, 0]).max() < 0.1


# --- files and currents ----------------------------------------------------------------------------
def test_several_csv_files_merge_on_time(tmp_path):
    traj = _motion(13)
    t = np.arange(1000) * 0.01
    cols = _log_cols(traj, t, _pin_tau(traj, t))
    _write_csv(tmp_path / "all.csv", t, cols)
    _write_csv(tmp_path / "pos.csv", t, {c: v for c, v in cols.items() if c.startswith("q_")})
    _write_csv(tmp_path / "eff.csv", t, {c: v for c, v in cols.items() if c.startswith("tau_")})
    # a third logger stamping half a step later: interpolated onto the first file's stamps
    late_tau = _pin_tau(traj, t + 0.005)
    _write_csv(tmp_path / "eff_late.csv", t + 0.005, {f"tau_{j}": late_tau[:, n] for n, j in enumerate(JOINTS)})
    one = load_case(_case(tmp_path / "a", [_torque_entry("../all.csv", "train"),
                                            _torque_entry("../all.csv", "validation", name="v")]),
                    allow_outside=True).datasets[0]
    two = load_case(_case(tmp_path / "b", [_torque_entry(["../pos.csv", "../eff.csv"], "train"),
                                            _torque_entry("../all.csv", "validation", name="v")]),
                    allow_outside=True).datasets[0]
    for k in ("t", "q", "tau"):
        np.testing.assert_array_equal(one.arrays[k], two.arrays[k])
    assert two.conditioning["merge"]["merged"].startswith("row by row") and len(two.files) == 2
    late = load_case(_case(tmp_path / "c", [_torque_entry(["../pos.csv", "../eff_late.csv"], "train"),
                                             _torque_entry("../all.csv", "validation", name="v")]),
                     allow_outside=True).datasets[0]
    assert "interpolated" in late.conditioning["merge"]["merged"]
    m = (t >= 0.005) & (t <= t[-1])
    # within linear interpolation's error h^2/8 |tau''| (tau'' by differences of the exact torques)
    ddtau = np.abs(np.diff(one.arrays["tau"], 2, axis=0)).max() / 0.01**2
    assert np.abs(late.arrays["tau"] - one.arrays["tau"][m]).max() <= 0.01**2 / 8 * ddtau * 1.1
    with pytest.raises(jflex.ConfigError, match=r"datasets\[0\]\.file.*list of files is for CSV"):
        load_case(_case(tmp_path / "d", [_torque_entry(["../pos.csv", "x.npz"], "train"),
                                          _torque_entry("../all.csv", "validation", name="v")]), allow_outside=True)


def test_coupled_currents_map_to_joint_torques_as_written(tmp_path):
    traj = _motion(14)
    t = np.arange(400) * 0.01
    rng = np.random.default_rng(15)
    i = rng.standard_normal((t.size, 3))  # three motor currents [A]
    k = np.array([20.0, 12.0, 8.0])  # torque constant x gear ratio [N m/A]
    i0 = np.array([0.05, -0.02, 0.1])  # current offsets [A]
    c = 0.5  # motor 3 also turns with joint 2 (a coupled wrist): its rate is qd3 + c qd2
    off = np.array([0.0, 1.5, -0.3])  # joint torque offsets [N m]
    cols = {**{f"q_{j}": traj(t, 0)[:, n] for n, j in enumerate(JOINTS)},
            **{f"i_{j}": i[:, n] for n, j in enumerate(JOINTS)}}
    _write_csv(tmp_path / "log.csv", t, cols)
    extra = {"scale": {f"i_{j}": float(k[n]) for n, j in enumerate(JOINTS)},
             "offset": {f"i_{j}": float(i0[n]) for n, j in enumerate(JOINTS)},
             "coupling": {"joints": ["joint2", "joint3"], "matrix": [[1.0, 0.0], [c, 1.0]]},
             "torque_offset": {"joint2": 1.5, "joint3": -0.3}}
    entry = _torque_entry("log.csv", "train", tau_cols={j: f"i_{j}" for j in JOINTS}, **extra)
    d = load_case(_case(tmp_path, [entry, dict(entry, split="validation", name="v")])).datasets[0]
    # by hand: motor torques m = k (i - i0); joint 2 = m2 + c m3 (K^T), joint 3 = m3; plus offsets
    m = k * (i - i0)
    hand = np.column_stack([m[:, 0], m[:, 1] + c * m[:, 2] + 1.5, m[:, 2] - 0.3])
    np.testing.assert_allclose(d.arrays["tau"], hand, rtol=1e-10, atol=1e-9)
    K = np.eye(3)
    K[2, 1] = c
    np.testing.assert_allclose(currents_to_torque(i, k, i0, K, off), hand, rtol=1e-12, atol=1e-12)
    assert d.channels["tau:joint2"].scale == 12.0 and d.channels["tau:joint2"].offset == -0.02
    with pytest.raises(jflex.ConfigError, match=r"coupling\.matrix.*singular"):
        bad = dict(entry, coupling={"joints": ["joint2", "joint3"], "matrix": [[1.0, 2.0], [0.5, 1.0]]})
        load_case(_case(tmp_path / "s", [bad, dict(bad, split="validation", name="v")]), allow_outside=True)


def test_a_forgotten_current_constant_is_refused(tmp_path):
    traj = _motion(16)
    t = np.arange(100) * 0.01
    _write_csv(tmp_path / "log.csv", t, _log_cols(traj, t, np.ones((t.size, 3))))
    entry = _torque_entry("log.csv", "train", scale={"tau_joint1": "TODO: torque constant [N m/A] x gear ratio"})
    with pytest.raises(jflex.ConfigError, match=r"datasets\[0\]\.scale\.tau_joint1.*not filled in"):
        load_case(_case(tmp_path, [entry, dict(entry, split="validation", name="v")]))


# --- NPZ -------------------------------------------------------------------------------------------
def test_a_torque_npz_with_permuted_columns_loads_in_model_order(tmp_path):
    traj = _motion(17)
    t = np.arange(200) * 0.01
    q, tau = traj(t, 0), _pin_tau(traj, t)
    perm = [2, 0, 1]
    reps = np.stack([tau + 0.01 * r for r in range(3)])
    np.savez(tmp_path / "p.npz", t=t, q=q[:, perm], tau=tau[:, perm], joints=np.array(JOINTS)[perm],
             tau_repeats=reps[:, :, perm])
    entries = [{"kind": "torque", "file": "p.npz", "split": "train"},
               {"kind": "torque", "file": "p.npz", "split": "validation", "name": "v"}]
    d = load_case(_case(tmp_path, entries)).datasets[0]
    np.testing.assert_array_equal(d.arrays["q"], q)
    np.testing.assert_array_equal(d.arrays["tau"], tau)
    np.testing.assert_array_equal(d.arrays["tau_repeats"], reps)


def test_h_repeats_of_the_wrong_shape_is_refused_at_load(tmp_path):
    f = np.linspace(5, 50, 30)
    H = (1e-6 / (1 + 1j * f))[:, None, None] * np.ones((1, 3, 3))
    np.savez(tmp_path / "frf.npz", q0=np.array([0.0, 0.7, -1.3]), freq=f, H=H, H_repeats=np.stack([H, H])[:, :20])
    (tmp_path / "robot.urdf").write_text(R.ARM3_URDF)
    cfg = {"robot": "robot.urdf", "tool_frame": "tool",
           "datasets": [{"kind": "frf", "file": "frf.npz", "split": "train"},
                        {"kind": "frf", "file": "frf.npz", "split": "validation", "name": "v"}]}
    (tmp_path / "case.yaml").write_text(yaml.safe_dump(cfg))
    with pytest.raises(jflex.DataError, match=r"field 'H_repeats': expected shape \(R, 30, 3, 3\)"):
        load_case(tmp_path)


def test_a_response_log_with_jitter_is_resampled(tmp_path):
    # an output-error response log (one joint channel, rest posture q0) whose stamps jitter by 20 %
    rng = np.random.default_rng(18)
    h, n = 0.002, 600
    t = h * np.arange(n) + np.r_[0.0, rng.uniform(-0.2, 0.2, n - 1)] * h
    u = np.sin(2 * np.pi * 3 * t)
    y = 0.1 * np.sin(2 * np.pi * 3 * t - 0.3)
    cols = {"u1": u, "u2": 0.5 * u, "u3": 0.2 * u, "y1": y}
    _write_csv(tmp_path / "r.csv", t, cols)
    entry = {"kind": "response", "file": "r.csv", "split": "train", "q0": [0.0, 0.7, -1.3],
             "columns": {"time": "time", "torque": {j: f"u{k + 1}" for k, j in enumerate(JOINTS)},
                         "output": {"joint1": "y1"}}}
    d = load_case(_case(tmp_path, [entry, dict(entry, split="validation", name="v")])).datasets[0]
    s = d.conditioning["sampling"]
    assert s["resampled"] and s["jitter_pct"] > 20
    tt = d.arrays["t"]
    assert np.ptp(np.diff(tt)) < 1e-9
    # linear interpolation of a 3 Hz sine sampled at 500 Hz: error below h^2/8 |y''| (steps up to 1.4 h)
    bound = (1.4 * h) ** 2 / 8 * 0.1 * (2 * np.pi * 3) ** 2
    assert np.abs(d.arrays["y"][:, 0] - 0.1 * np.sin(2 * np.pi * 3 * tt - 0.3)).max() < bound


def test_given_cutoff_reads_the_torque_noise_below_it(tmp_path, monkeypatch):
    # an angle spectrum that decays smoothly never meets the angle-noise level: the motion band
    # read off it runs up to Nyquist (2.5 kHz on a real 5 kHz log), and the torque-noise band (1.5-4
    # x it) lay above Nyquist, reading 0 N m under a given 100 Hz cutoff; the band now follows the
    # given cutoff when the motion band does not lie below it
    import jflex.data._angle_log as A
    from jflex.gap.torque._set import torque_set

    monkeypatch.setattr(A, "motion_band", lambda q, h, sig, **kw: 0.48 / h)  # the estimator's failure

    traj, fs = _motion(3), 500.0
    t = np.arange(int(8 * fs)) / fs
    noise = 0.05 * np.random.default_rng(4).standard_normal((t.size, 3))
    _write_csv(tmp_path / "log.csv", t, _log_cols(traj, t, _pin_tau(traj, t) + noise))
    case = load_case(_case(tmp_path, [_torque_entry("log.csv", "train"), _torque_entry("log.csv", "validation", name="v")],
                           options={"filter_cutoff_hz": 20.0}))
    s = torque_set(case.robot, case.datasets[0], cutoff_hz=20.0)
    got = np.asarray(s.processing["torque_noise_nm"])
    # white noise of std 0.05 through a 20 Hz low-pass at 500 Hz keeps about sqrt(20 / 250) of it
    assert np.all(got > 0.3 * 0.05 * np.sqrt(20 / 250)) and np.all(got < 3 * 0.05 * np.sqrt(20 / 250)), got


def test_spectrum_floor_band_ends_where_the_motions_power_ends():
    # A 5 kHz log of interpolated angles (no sensor noise; at rest for 5 s, so the second
    # difference's robust spread reads 0 and the motion band gives no answer), whose servoed
    # motion adds a tail of power ~ f^-4 that stays 100 x above the spectrum's floor to ~130 Hz.
    # The motion's harmonics reach 1.25 Hz: the cutoff keeps them and stays far below the tail.
    fs = 5000.0
    t = np.arange(int(9 * fs)) / fs
    rng = np.random.default_rng(3)
    tm = np.where(t > 5.0, t - 5.0, 0.0)
    q = np.zeros((t.size, 3))
    for j in range(3):
        for k in range(1, 6):
            q[:, j] += 0.3 / k * (1 - np.cos(2 * np.pi * 0.25 * k * tm)) * rng.uniform(0.8, 1.2)
        w = np.cumsum(np.cumsum(rng.standard_normal(t.size))) / fs**2
        w -= np.polyval(np.polyfit(t, w, 3), t)
        q[:, j] += np.where(t > 5.0, 1e-4 * w / w.std(), 0.0)
    fc, info = choose_cutoff(q, 1 / fs)
    assert info["method"] == "spectrum_floor"
    assert info["floor_band_hz"] > 80  # where the tail meets the floor
    assert 2.5 * 1.25 < fc < 60, info
