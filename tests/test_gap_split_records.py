"""A log with gaps too long to bridge is split at them into data sets of its own (one per stretch
between gaps, named <name>#k), each keeping the log's split; a stretch too short for the low-pass
is dropped with a warning naming it; a gap short against the motion is still bridged. The logs are
made here: a 3-joint arm's torques by Pinocchio's RNEA on a 0.5 Hz motion given in closed form,
angles on an 18-bit encoder, sampled at 1 kHz, samples then cut out to make the gaps."""

from __future__ import annotations

import pathlib
import sys
import warnings

import numpy as np
import pinocchio as pin
import pytest
import yaml

import jflex
from jflex.gap import diagnose, load_case
from jflex.gap.report._html import conditioning_table, data_notes

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "gap"))
from independent import robots as R  # noqa: E402

FS = 1000.0
F0 = 0.5  # [Hz] the motion's fundamental (and its second harmonic)
HOME = np.array([0.0, 0.7, -1.3])
AMP = np.array([0.6, 0.4, 0.5])
PHASE = np.array([0.0, 1.0, 2.0])
STEP = 2 * np.pi / 2**18  # encoder count [rad]


def _motion(t):
    w = 2 * np.pi * F0
    a, b = w * t[:, None] + PHASE, 2 * (w * t[:, None] + PHASE)
    q = HOME + AMP * (np.sin(a) + 0.3 * np.sin(b))
    qd = AMP * w * (np.cos(a) + 0.6 * np.cos(b))
    qdd = -AMP * w**2 * (np.sin(a) + 1.2 * np.sin(b))
    return q, qd, qdd


def _log(n, seed=0):
    """``(t, q, tau)``: ``n`` samples at 1 kHz, quantised angles, RNEA torques plus 0.02 N m noise."""
    model = pin.buildModelFromXML(R.ARM3_URDF)
    data = model.createData()
    t = np.arange(n) / FS
    q, qd, qdd = _motion(t)
    tau = np.array([pin.rnea(model, data, q[k], qd[k], qdd[k]) for k in range(n)])
    tau += 0.02 * np.random.default_rng(seed).standard_normal(tau.shape)
    return t, np.round(q / STEP) * STEP, tau


def _case(folder, logs):
    """A case of the arm (its URDF as the nominal model) with one NPZ torque set per ``(name, split, (t, q, tau))``."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "arm3.urdf").write_text(R.ARM3_URDF)
    ds = []
    for name, split, (t, q, tau) in logs:
        np.savez(folder / f"{name}.npz", t=t, q=q, tau=tau)
        ds.append(dict(kind="torque", file=f"{name}.npz", split=split))
    (folder / "case.yaml").write_text(yaml.safe_dump(dict(robot="arm3.urdf", nominal_effects=[], datasets=ds),
                                                     sort_keys=False))
    return folder


def _load(folder):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        case = load_case(folder)
    return case, [str(w.message) for w in caught if issubclass(w.category, UserWarning)]


def _cut(n, *spans):
    """Row indices of ``range(n)`` without the half-open ``spans``."""
    keep = np.ones(n, bool)
    for a, b in spans:
        keep[a:b] = False
    return np.flatnonzero(keep)


def _result(case):
    """What the report shows of a case's conditioning (diagnosis.json's 'conditioning' before any fit)."""
    return {"conditioning": {d.name: d.conditioning for d in case.datasets}}


def test_two_long_gaps_split_a_log_into_three_data_sets_without_interpolating_across_them(tmp_path):
    t, q, tau = _log(12000)
    # 0.4 s gaps after 4 s and 8 s: 20 % of the 2 s period, far beyond 5 % of the 1 Hz harmonic's
    keep = _cut(12000, (4001, 4401), (8001, 8401))
    val = _log(6000, seed=1)
    case, caught = _load(_case(tmp_path / "c", [("run", "train", (t[keep], q[keep], tau[keep])),
                                                ("val", "validation", val)]))
    names = [d.name for d in case.datasets]
    assert names == ["run#1", "run#2", "run#3", "val"]
    assert [d.split for d in case.datasets] == ["train"] * 3 + ["validation"]
    pieces = [(0, 4001), (4401, 8001), (8401, 12000)]
    for d, (a, b) in zip(case.datasets, pieces):
        # the stretch's own samples, as logged: nothing interpolated into (or across) a gap
        assert d.arrays["t"].size == b - a
        np.testing.assert_array_equal(d.arrays["t"], t[a:b])
        np.testing.assert_array_equal(d.arrays["q"], q[a:b])
        np.testing.assert_array_equal(d.arrays["tau"], tau[a:b])
        assert d.file.name == "run.npz"
        src = d.conditioning["sampling"]["split_from"]
        assert src["record"] == "run" and src["stretches"] == 3 and src["samples_in"] == b - a
        assert [g["action"] for g in src["gaps"]] == ["split", "split"]
        assert [g["t_s"] for g in src["gaps"]] == pytest.approx([4.0, 8.0])
        assert [g["length_s"] for g in src["gaps"]] == pytest.approx([0.401, 0.401])
    np.testing.assert_array_equal(case.datasets[3].arrays["tau"], val[2])
    assert "split_from" not in case.datasets[3].conditioning["sampling"]
    # the split is a Python warning, kept in Case.warnings, that names both gaps and every data set
    split = [w for w in caught if "is split at 2 gap(s)" in w]
    assert len(split) == 1 and split[0] in case.warnings
    for word in ("0.401 s after t = 4 s", "0.401 s after t = 8 s", "'run#1' (0 to 4 s)", "'run#2' (4.401 to 8 s)",
                 "'run#3' (8.401 to 11.999 s)"):
        assert word in split[0], (word, split[0])
    # the report: the table's stamps column names each stretch, the data notes the split
    rows = {r[0]: r for r in conditioning_table(_result(case))}
    assert "stretch 2 of 3 of 'run' (4.401 to 8 s), cut at 2 gap(s)" in rows["run#2"][2]
    assert any("Warning ('run#1')" in n and "0.401 s after t = 8 s" in n for n in data_notes(_result(case)))


def test_a_validation_log_split_stays_validation_and_a_20_sample_stretch_is_dropped(tmp_path):
    train = _log(6000)
    t, q, tau = _log(9000, seed=2)
    # 4000 samples, a 0.4 s gap, 20 samples, a 0.4 s gap, the rest
    keep = _cut(9000, (4000, 4400), (4420, 4820))
    case, caught = _load(_case(tmp_path / "c", [("run", "train", train), ("val", "validation",
                                                                         (t[keep], q[keep], tau[keep]))]))
    assert [d.name for d in case.datasets] == ["run", "val#1", "val#3"]
    assert [d.split for d in case.datasets] == ["train", "validation", "validation"]
    assert [d.arrays["t"].size for d in case.datasets] == [6000, 4000, 9000 - 4820]
    np.testing.assert_array_equal(case.datasets[2].arrays["q"], q[4820:])
    dropped = [w for w in caught if "dropped" in w]
    assert len(dropped) == 1 and "'val#2' (4.4 to 4.419 s, 20 samples" in dropped[0], caught
    assert dropped[0] in case.warnings
    assert "'val#1' (0 to 3.999 s), 'val#3' (4.82 to 8.999 s)" in next(w for w in caught if "is split" in w)


def test_a_short_gap_is_still_bridged_and_a_log_without_long_gaps_kept_whole(tmp_path):
    t, q, tau = _log(6000)
    keep = _cut(6000, (3001, 3009))  # 8 samples lost: a 9 ms step, 1.8 % of the 1 Hz harmonic's period
    val = _log(4000, seed=1)
    case, caught = _load(_case(tmp_path / "c", [("run", "train", (t[keep], q[keep], tau[keep])),
                                                ("val", "validation", val)]))
    assert [d.name for d in case.datasets] == ["run", "val"]
    assert not any("split" in w for w in caught)
    run = case.datasets[0]
    gaps = run.conditioning["sampling"]["gaps"]
    assert len(gaps) == 1 and gaps[0]["action"].startswith("bridged") and gaps[0]["length_s"] == pytest.approx(0.009)
    np.testing.assert_allclose(run.arrays["t"], t, atol=1e-9)
    # straight lines across the gap, between the samples either side of it
    k = np.arange(3001, 3009)
    np.testing.assert_allclose(run.arrays["q"][k], q[3000] + (q[3009] - q[3000]) * ((k - 3000) / 9.0)[:, None],
                               atol=1e-9)
    assert "1 gap(s) bridged (longest 0.009 s)" in conditioning_table(_result(case))[0][2]


def test_a_log_whose_stretches_are_all_too_short_is_refused_naming_the_gaps(tmp_path):
    t, q, tau = _log(890)
    keep = _cut(890, (30, 430), (460, 860))  # three stretches of 30 samples
    folder = _case(tmp_path / "c", [("run", "train", (t[keep], q[keep], tau[keep])), ("val", "validation", _log(4000))])
    with pytest.raises(jflex.DataError, match=r"run\.npz: field 't': 2 gap\(s\) too long to bridge .*0\.401 s after "
                       r"t = 0\.029 s; 0\.401 s after t = 0\.459 s\) cut the log into 3 stretches, none long enough to "
                       r"be processed: 'run#1' \(0 to 0\.029 s, 30 samples: its low-pass"):
        load_case(folder)


@pytest.mark.long
def test_a_split_case_is_diagnosed(tmp_path):
    # the nominal model is the arm that made the torques: with both logs cut in two, the diagnosis
    # judges the gap on both stretches of the validation log and finds it within the noise
    t, q, tau = _log(5000)
    tv, qv, tauv = _log(4400, seed=1)
    keep, keep_v = _cut(5000, (2500, 2900)), _cut(4400, (2000, 2400))
    folder = _case(tmp_path / "c", [("run", "train", (t[keep], q[keep], tau[keep])),
                                    ("val", "validation", (tv[keep_v], qv[keep_v], tauv[keep_v]))])
    cfg = yaml.safe_load((folder / "case.yaml").read_text())
    cfg["options"] = {"decimate": 4}
    (folder / "case.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    case, _ = _load(folder)
    assert [(d.name, d.split) for d in case.datasets] == [("run#1", "train"), ("run#2", "train"),
                                                          ("val#1", "validation"), ("val#2", "validation")]
    res = diagnose(case, max_effects=0, prune=2).result
    assert set(res["conditioning"]) == {"run#1", "run#2", "val#1", "val#2"}
    floors = res["noise_floor_per_dataset"]
    assert set(floors) == {"val#1", "val#2"} and all(0 < f < 1 for f in floors.values()), floors
    assert res["verdict"] == "within_noise", (res["verdict"], res["gap_before"], res["noise_floor"])
