"""The real-log-traits generator (benchmarks/gap/independent/reallog.py): its physics agrees with
Pinocchio and with closed forms, its logs have the traits asked for, and every case folder it
writes is a case that jflex.gap.load_case reads (or the reason it cannot yet)."""

import csv
import json
import pathlib
import sys

import numpy as np
import pytest
import yaml
from scipy.interpolate import CubicSpline

import jflex

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "gap"))
from independent import reallog as RL  # noqa: E402
from independent.torque import rnea_batch  # noqa: E402


def _read_csv(path):
    with open(path) as f:
        rows = list(csv.reader(f))
    return rows[0], np.asarray(rows[1:], float)


def _arm(seed=0):
    rng = np.random.default_rng(seed)
    true, tool, home, cad, _ = RL._setup("arm3", rng)
    tr = RL._trajs(rng, true, home, 2.0)[0]
    Fv, Fc, scale, qdstd = RL._friction(rng, true, tr, 2.0)
    return rng, true, home, cad, tr, (Fv, Fc), scale, qdstd


def test_fast_reference_is_the_fourier_trajectory():
    _, _, _, _, tr, _, _, _ = _arm()
    for t in (0.0, 0.37, 1.9):
        for d, v in enumerate(RL.reference(tr, t)):
            np.testing.assert_allclose(v, tr(t, d)[0], rtol=1e-12, atol=1e-12)


def test_closed_loop_command_is_the_plants_inverse_dynamics():
    # the logged torque (the PID command) equals Pinocchio's RNEA of the simulated motion plus the
    # friction and the planted effect; the motion is an integral (rates = d/dt angles) and it is
    # not the reference (the controller tracks it with an error)
    rng, true, home, cad, tr, fric, scale, qdstd = _arm(1)
    eff = [RL._effect(rng, true, "viscous_friction", 1, scale, qdstd, fric)]
    t = np.arange(600) / 2000.0
    q, qd, qdd, u, r = RL.closed_loop(true, cad, tr, home, t, fric, eff)
    tau = rnea_batch(true, q, qd, qdd) + RL.friction(*fric, qd) + RL.planted_torque(eff, q, qd, t)
    np.testing.assert_allclose(u, tau, atol=1e-9 * np.abs(u).max())
    inner = slice(10, -10)
    np.testing.assert_allclose(CubicSpline(t, q)(t, 1)[inner], qd[inner], atol=1e-5 * np.abs(qd).max())
    # accelerations away from velocity reversals (the smooth Coulomb law turns within ~10 ms there)
    away = (np.abs(qd) > 0.05)[inner]
    np.testing.assert_allclose(CubicSpline(t, qd)(t, 1)[inner][away], qdd[inner][away], atol=1e-3 * np.abs(qdd).max())
    err = np.abs(q - r).max()
    assert 1e-4 < err < 0.05 * np.ptp(r, axis=0).max()


def test_current_map_inverts_and_couples_the_wrist():
    rng = np.random.default_rng(2)
    n = 4
    gear, k, i0 = rng.uniform(50, 150, n), rng.uniform(0.05, 0.2, n), rng.uniform(-0.05, 0.05, n)
    K, kk = RL.current_map(n, gear, k, coupled=(2, 3), c=0.6)
    tau = rng.normal(size=(50, n))
    i = RL.current_from_torque(K, kk, tau, i0)
    np.testing.assert_allclose(RL.torque_from_current(K, kk, i, i0), tau, atol=1e-12)
    # tau = K^T k (i - i0) written out: the wrist motor 4 loads joint 3 through the coupling
    m = k * (i - i0)
    np.testing.assert_allclose(tau[:, 2], gear[2] * m[:, 2] + 0.6 * gear[3] * m[:, 3], atol=1e-12)
    np.testing.assert_allclose(tau[:, 3], gear[3] * m[:, 3], atol=1e-12)
    np.testing.assert_allclose(tau[:, :2], gear[:2] * m[:, :2], atol=1e-12)


def test_currents_case_states_data_sheet_constants_a_few_percent_off(tmp_path):
    folder, truth = RL.make_reallog_case(tmp_path / "c", "coupled_wrist", seed=3)
    tr = truth["transmission"]
    off = np.asarray(tr["torque_constant_datasheet"]) / np.asarray(tr["torque_constant_true"]) - 1
    assert np.all((np.abs(off) >= 0.02) & (np.abs(off) <= 0.05))
    K = np.asarray(tr["K"])
    assert K[2, 1] != 0 and np.count_nonzero(K - np.diag(np.diag(K))) == 1
    header, a = _read_csv(folder / "traj0.csv")
    i = a[:, [header.index(f"motor{m + 1}_current") for m in range(3)]]
    # the recorded currents map back to torques of the size the rigid-body physics gave (std per joint
    # of this record, before friction and noise)
    tau = RL.torque_from_current(K, np.asarray(tr["torque_constant_true"]), i, np.asarray(tr["current_offset_a"]))
    np.testing.assert_allclose(tau.std(axis=0), truth["realism"]["torque_std"], rtol=0.3)


def test_jitter_statistics(tmp_path):
    folder, truth = RL.make_reallog_case(tmp_path / "j", "jitter", seed=4)
    fs = truth["nominal_rate_hz"]
    for rec in ("traj0", "traj1", "traj2"):
        _, a = _read_csv(folder / f"{rec}.csv")
        dt = np.diff(a[:, 0]) * fs
        rep = dt == 0
        assert 0.002 < rep.mean() < 0.03  # about 1 % repeated rows
        np.testing.assert_array_equal(a[1:][rep], a[:-1][rep])  # a repeated row repeats every value
        stale = np.all(a[1:, 1:] == a[:-1, 1:], axis=1) & ~rep  # the previous values at a new stamp
        assert 0.002 < stale.mean() < 0.03
        kept = dt[(dt > 0) & (dt < 1.5)]
        dev = np.abs(kept - 1)
        assert 0.15 < dev.max() <= RL.JITTER + 1e-9  # steps vary by up to 20 %
        drops = dt[dt >= 1.5]
        assert 0.005 < drops.size / dt.size < 0.05
        assert RL.DROP_BURST + 1 - RL.JITTER <= dt.max() <= RL.DROP_BURST + 1 + RL.JITTER  # the burst
    twin, ttruth = RL.make_reallog_case(tmp_path / "u", "jitter_twin", seed=4)
    assert ttruth["effects"] == truth["effects"] and ttruth["cad_error"] == truth["cad_error"]
    _, b = _read_csv(twin / "traj0.csv")
    np.testing.assert_allclose(np.diff(b[:, 0]) * fs, 1.0, atol=1e-6)


@pytest.mark.parametrize("trait", ["dead_zero", "dead_stuck"])
def test_the_dead_channel_is_dead(tmp_path, trait):
    folder, truth = RL.make_reallog_case(tmp_path / trait, trait, seed=5)
    (dead,) = truth["dead_channels"]
    assert dead["joint"] == "joint3"
    # the planted viscous friction at the shoulder is not in the nominal model
    nominal = yaml.safe_load((folder / "case.yaml").read_text())["nominal_effects"]
    assert {"effect": "viscous_friction", "joint": ["joint1", "joint3"]} in nominal
    for rec in ("traj0", "traj1", "traj2"):
        with np.load(folder / f"{rec}.npz") as z:
            col = z["tau"][:, 2]
            others = z["tau"][:, :2]
        if trait == "dead_stuck":
            assert np.all(col == RL.STUCK_VALUE)
        else:
            assert abs((col == 0.0).mean() - RL.DEAD_FRACTION) < 0.04
            assert (col != 0).any()
        assert np.all(others != 0.0)


def test_drifting_friction_grows_by_thirty_percent(tmp_path):
    rng = np.random.default_rng(0)
    qd = rng.normal(size=(5, 3))
    e = [dict(effect="friction_drift", j=1, params={"Fv0": 2.0, "s0": 0.0, "s1": 12.0})]
    tau0 = RL.planted_torque(e, qd, qd, np.zeros(5))
    tau1 = RL.planted_torque(e, qd, qd, np.full(5, 12.0))
    np.testing.assert_allclose(tau0, 0.0)
    np.testing.assert_allclose(tau1[:, 1], RL.DRIFT * 2.0 * qd[:, 1])


def test_periodic_records_repeat_up_to_the_stated_noise(tmp_path):
    # the scatter between periods is the torque noise of truth.json (white, known std)
    folder, truth = RL.make_reallog_case(tmp_path / "p", "periodic", seed=6)
    L, P = truth["samples_per_period"], truth["periods"]
    with np.load(folder / "traj2.npz") as z:
        tau = z["tau"].reshape(P, L, -1)
    scatter = np.sqrt(((tau - tau.mean(axis=0)) ** 2).sum(axis=0).mean(axis=0) / (P - 1))
    np.testing.assert_allclose(scatter, list(truth["noise_std_nm"].values()), rtol=0.1)


def test_multirate_records(tmp_path):
    folder, truth = RL.make_reallog_case(tmp_path / "m", "multirate", seed=7)
    rates = []
    for f in sorted(folder.glob("*.npz")):
        with np.load(f) as z:
            rates.append(1.0 / np.diff(z["t"]).mean())
    np.testing.assert_allclose(rates, [250.0, 250.0, 1000.0])


def test_null_case_masses_ten_percent_off(tmp_path):
    _, truth = RL.make_reallog_case(tmp_path / "n", "null_cad_ar1", seed=8)
    assert truth["family"] == "null" and truth["effects"] == [] and truth["expected_verdict"] == "within_noise"
    for link in truth["cad_error"]:
        assert abs(abs(link["mass_cad"] / link["mass_true"] - 1) - 0.10) < 1e-12
        assert link["com_cad"] == link["com_true"]


def _marks(t):
    if t in ("closed_loop", "cogging"):
        return pytest.param(t, marks=pytest.mark.heavy)  # three simulated records: 10-20 s each
    return t


@pytest.mark.parametrize("trait", [_marks(t) for t in RL.TRAITS])
def test_every_case_loads(tmp_path, trait):
    folder, truth = RL.make_reallog_case(tmp_path / trait, trait, seed=11)
    case = jflex.gap.load_case(folder)
    assert {d.split for d in case.datasets} == {"train", "validation"}
    assert "truth" not in (folder / "case.yaml").read_text()
    assert json.loads((folder / "truth.json").read_text()) == truth


@pytest.mark.parametrize("trait", ["coupled_wrist", "jitter"])
def test_cases_in_the_plain_format_load(tmp_path, trait):
    # one CSV per record, diagonal scale only (what a jflex without offsets and couplings read)
    folder, _ = RL.make_reallog_case(tmp_path / trait, trait, seed=11, fmt="current")
    jflex.gap.load_case(folder)


def test_coupled_drive_torque_is_the_motor_friction_through_the_coupling():
    # virtual work: the joint torques' power equals the motor friction's power f(w) w
    rng = np.random.default_rng(9)
    qd = rng.normal(size=(40, 3))
    p = {"a": 1, "c": 0.5, "fv": 0.3, "fc": 0.2}
    tau = RL.planted_torque([dict(effect="coupled_drive", j=2, params=p)], qd, qd, np.zeros(40))
    w = qd[:, 2] + 0.5 * qd[:, 1]
    f = 0.3 * w + 0.2 * np.tanh(w / RL.COULOMB_WIDTH)
    np.testing.assert_allclose((tau * qd).sum(axis=1), f * w, atol=1e-12)
    np.testing.assert_allclose(tau[:, 0], 0.0)


@pytest.mark.parametrize("trait", ["currents", "coupled_wrist"])
def test_extended_currents_case_loads_as_the_transmission_maps(tmp_path, trait):
    # case.yaml states offsets, data-sheet constants and the coupling: the loaded torques are
    # tau = K^T k_sheet (i - i0) as written out above, from the CSV's raw currents
    folder, truth = RL.make_reallog_case(tmp_path / trait, trait, seed=12, fmt="extended")
    tr = truth["transmission"]
    case = jflex.gap.load_case(folder)
    for d in case.datasets:
        header, a = _read_csv(folder / f"{d.name}.csv")
        i = a[:, [header.index(f"motor{m + 1}_current") for m in range(3)]]
        want = RL.torque_from_current(np.asarray(tr["K"]), np.asarray(tr["torque_constant_datasheet"]), i,
                                      np.asarray(tr["current_offset_a"]))
        np.testing.assert_allclose(d.arrays["tau"], want, rtol=1e-9, atol=1e-9)


def test_bench_filter_share_of_white_noise_is_the_closed_form():
    # the runner's true floor passes the noise through the diagnosis' low-pass (Butterworth order
    # 4 run both ways): for white noise and fc << fs the share of variance kept is
    # (fc / (fs/2)) * int_0^inf (1 + x^8)^-2 dx = (fc / (fs/2)) * (7/8) (pi/8) / sin(pi/8)
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
    import bench_gap_reallog as B

    fs, fc = 1000.0, 10.0
    want = fc / (fs / 2) * (7 / 8) * (np.pi / 8) / np.sin(np.pi / 8)
    got = B._passed_fraction({"realism": {"noise": "white"}}, fs, fc)
    assert abs(got / want - 1) < 0.01
    # coloured noise keeps more of its variance below the cutoff
    assert B._passed_fraction({"realism": {"noise_ar1_pole": 0.8}}, fs, fc) > 3 * got


def test_velocity_log_is_one_kilohertz_with_noisy_rates(tmp_path):
    folder, truth = RL.make_reallog_case(tmp_path / "v", "velocities", seed=13)
    assert truth["nominal_rate_hz"] == 1000.0
    hp, p = _read_csv(folder / "raw" / "traj0_position.csv")
    hv, v = _read_csv(folder / "raw" / "traj0_velocity.csv")
    np.testing.assert_array_equal(p[:, 0], v[:, 0])  # one stamp per row in every topic
    # rates differenced once more: noise of the order of 3e-3 rad/s x 1 kHz (4 rad/s^2 on the real log)
    fresh = np.diff(v[:, 0]) > 0
    d2 = np.diff(v[:, 1:], axis=0)[fresh] / np.diff(v[:, 0])[fresh, None]
    noise = 1.4826 * np.median(np.abs(np.diff(d2, axis=0)), axis=0) / np.sqrt(2)
    assert np.all((noise > 2.0) & (noise < 10.0))
    cfg = yaml.safe_load((folder / "case.yaml").read_text())
    assert cfg["datasets"][0]["file"] == ["raw/traj0_position.csv", "raw/traj0_velocity.csv", "raw/traj0_effort.csv"]
