"""The null family of the gap bench (benchmarks/gap/independent/null.py): its case folders load, the
true robot differs from the case's URDF by the stated CAD error and nothing else, and the logging
traits are really in the records (checked on the files, with Pinocchio and NumPy)."""

import csv
import json
import pathlib
import sys

import numpy as np
import pytest
import yaml

pin = pytest.importorskip("pinocchio")
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "gap"))
from independent import null  # noqa: E402

from jflex.gap import load_case  # noqa: E402


def _traits(**kw):
    return dict(null.PLAIN, **kw)


@pytest.fixture(scope="module")
def npz_case(tmp_path_factory):
    spec = dict(id="t_npz", robot="planar2", seed=11,
                traits=_traits(angles="encoder", torque="adc12", hum=True, clip=True, excitation="periodic"))
    return null.make_null_case(tmp_path_factory.mktemp("null") / "npz", spec)


@pytest.fixture(scope="module")
def csv_case(tmp_path_factory):
    spec = dict(id="t_csv", robot="arm3", seed=12,
                traits=_traits(noise="ar1", torque="current12", stamps="jitter", clip=True))
    return null.make_null_case(tmp_path_factory.mktemp("null") / "csv", spec)


def _read_csv(path):
    with open(path) as f:
        r = list(csv.reader(f))
    return r[0], np.array(r[1:], float)


def test_plan_spreads_robots_and_traits():
    p = null.plan("full")
    assert len(p) >= 30 and len({s["id"] for s in p}) == len(p)
    assert len({s["robot"] for s in p}) >= 5
    for k, vals in null.TRAITS.items():
        seen = {s["traits"][k] for s in p}
        assert seen == set(vals), k
    # the traits combine: most cases carry three or more non-plain traits
    assert sum(sum(s["traits"][k] != null.PLAIN[k] for k in null.TRAITS) >= 3 for s in p) >= 15


@pytest.mark.parametrize("which", ["npz_case", "csv_case"])
def test_case_loads_and_truth_is_null(which, request):
    folder, truth = request.getfixturevalue(which)
    case = load_case(folder)
    assert truth["family"] == "null" and truth["effects"] == []
    assert json.loads((folder / "truth.json").read_text())["effects"] == []
    cfg = yaml.safe_load((folder / "case.yaml").read_text())
    # the true friction is the nominal model's: both laws at every joint
    assert {e["effect"] for e in cfg["nominal_effects"]} == {"viscous_friction", "coulomb_friction"}
    assert all(e["joint"] == "all" for e in cfg["nominal_effects"])
    assert case is not None


@pytest.mark.parametrize("which", ["npz_case", "csv_case"])
def test_cad_error_is_the_only_model_difference(which, request):
    folder, truth = request.getfixturevalue(which)
    true, _, _ = null.true_model(truth["robot"])
    cad = pin.buildModelFromUrdf(str(folder / "robot.urdf"))
    assert cad.nq == true.nq
    for i in range(1, true.njoints):
        a, b = true.inertias[i], cad.inertias[i]
        assert 0.02 - 1e-9 <= abs(b.mass / a.mass - 1) <= 0.10 + 1e-9
        assert 0.005 - 1e-9 <= np.linalg.norm(b.lever - a.lever) <= 0.02 + 1e-9
        # the rotational inertia about the COM scales with the mass
        np.testing.assert_allclose(b.inertia, a.inertia * b.mass / a.mass, rtol=1e-8, atol=1e-12)
        assert cad.jointPlacements[i].isApprox(true.jointPlacements[i], 1e-9)
    # the CAD robot's torques differ from the truth's along a motion (the error is not nil) ...
    q = pin.neutral(true) + 0.3
    g_true = pin.computeGeneralizedGravity(true, true.createData(), q)
    g_cad = pin.computeGeneralizedGravity(cad, cad.createData(), q)
    assert np.max(np.abs(g_cad - g_true)) > 1e-3 * np.max(np.abs(g_true))


def test_npz_traits_present(npz_case):
    folder, truth = npz_case
    tr = truth["traits"]
    z = np.load(folder / "traj2.npz")
    t, q, qd, tau = z["t"], z["q"], z["qd"], z["tau"]
    # encoder counts: angles on the grid, velocities the backward differences of the counts
    step = 2 * np.pi / tr["encoder_counts_per_rev"]
    assert 2**16 <= tr["encoder_counts_per_rev"] <= 2**18
    np.testing.assert_allclose(q / step, np.round(q / step), atol=1e-6)
    np.testing.assert_allclose(qd[1:], np.diff(q, axis=0) / np.diff(t)[:, None], rtol=1e-9, atol=1e-9)
    # 12-bit torques: on each channel's grid, never more than 2047 codes off zero
    for m, name in enumerate(truth["noise_std_nm"]):
        s = tr["adc"]["step"][name]
        codes = tau[:, m] / s
        np.testing.assert_allclose(codes, np.round(codes), atol=1e-6)
        assert np.abs(np.round(codes)).max() <= 2047
    # the clipped channel sits at its limit (the end code) for the stated share
    c = tr["clip_channel"]
    x = np.abs(tau[:, c["index"]])
    share = np.mean(x >= x.max() * (1 - 1e-9))
    assert 0.01 <= c["share_target"] <= 0.04
    assert abs(share - c["share_target"]) < 0.005 and share == pytest.approx(c["share"][2])
    np.testing.assert_allclose(x.max(), c["limit"][2], rtol=1e-9)
    # 50 Hz hum of the stated amplitude: the record holds whole hum periods and motion below 5 Hz
    for m, name in enumerate(truth["noise_std_nm"]):
        if m == c["index"]:
            continue
        amp = 2 * np.abs(np.mean(tau[:, m] * np.exp(-2j * np.pi * null.HUM_HZ * t)))
        assert amp == pytest.approx(tr["hum_nm"][name], rel=0.15, abs=3 * truth["noise_std_nm"][name] / np.sqrt(t.size))
    # periodic excitation: three periods of the same motion
    n_per = int(round(tr["period_s"] * tr["fs_hz"]))
    assert t.size == tr["periods"] * n_per
    np.testing.assert_allclose(q[n_per:2 * n_per], q[2 * n_per:], atol=2 * step)


def test_csv_traits_present(csv_case):
    folder, truth = csv_case
    tr = truth["traits"]
    hdr, a = _read_csv(folder / "traj2.csv")
    t = a[:, 0]
    cur = a[:, [k for k, h in enumerate(hdr) if h.endswith("_current")]]
    dt = np.diff(t)
    h = 1.0 / tr["fs_hz"]
    # jittered stamps: repeated rows, steps off the nominal one, one burst of dropped samples
    assert np.sum(dt == 0) >= 5 and np.all(dt >= 0)
    kept = dt[(dt > 0) & (dt < 1.5 * h)]
    assert np.max(np.abs(kept / h - 1)) > 0.1
    assert 3.5 * h < dt.max() < 4.5 * h
    # 12-bit currents: each channel on its grid
    for m, name in enumerate(truth["noise_std_nm"]):
        s = tr["adc"]["step"][name]
        np.testing.assert_allclose(cur[:, m] / s, np.round(cur[:, m] / s), atol=1e-5)
    # the clipped current sits at its limit for the stated share
    c = tr["clip_channel"]
    x = np.abs(cur[:, c["index"]])
    assert np.mean(x >= x.max() * (1 - 1e-9)) == pytest.approx(c["share"][2], abs=1e-12)
    assert abs(c["share"][2] - c["share_target"]) < 0.01
    # case.yaml states the exact transmission: scale (raw - offset) is the torque
    d = yaml.safe_load((folder / "case.yaml").read_text())["datasets"][2]
    tm = tr["transmission"]
    for m in range(len(tm["gear"])):
        col = f"motor{m + 1}_current"
        assert d["scale"][col] == pytest.approx(tm["gear"][m] * tm["torque_constant"][m], rel=1e-12)
        assert d["offset"][col] == pytest.approx(tm["current_offset_a"][m], rel=1e-12)
