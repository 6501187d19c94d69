"""End to end through ``jflex diagnose CASE --out RUN`` (case.yaml + topic CSVs): a log whose stamps
jitter by 20 % of the step, with dropped samples, a burst of three lost, repeated rows and stale
readings, gives the diagnosis of its uniformly sampled twin (same robot, motion, planted effect and
noise) and names the planted effect. The logs come from the independent generator
(benchmarks/gap/independent/reallog.py: Pinocchio and SciPy, no jflex), which knows the truth: the
planted effect, how many rows it repeated and that the twin's stamps are uniform."""

import json
import subprocess
import sys

import pytest

from independent import reallog as RL

SEEDS = {c["trait"]: c["seed"] for c in RL.plan("small")}  # the bench's small cases (arm3)


def _diagnose(folder, out):
    r = subprocess.run([sys.executable, "-m", "jflex.cli", "diagnose", str(folder), "--out", str(out)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads((out / "diagnosis.json").read_text())


def _named(res):
    return [(s["effect"], s["joint"]) for s in res["selected"]]


def _jittered(tmp_path):
    folder, truth = RL.make_reallog_case(tmp_path / "jitter", "jitter", seed=SEEDS["jitter"], small=True)
    return truth, _diagnose(folder, tmp_path / "run_jitter")


def _check_jittered(truth, res):
    # the data layer saw the irregular stamps for what they are and resampled them: each record's
    # repeated stamps are the rows the generator logged twice, its repeated readings the stale ones
    recs = [res["conditioning"][f"traj{i}_position"]["sampling"] for i in range(3)]
    assert all(r["resampled"] for r in recs)
    assert [r["repeated_stamps"] for r in recs] == [s["repeated_rows"] for s in truth["stamps"]]
    assert [r["repeated_rows"] for r in recs] == [s["stale_rows"] for s in truth["stamps"]]
    # the jitter reported is the clock's (steps that dropped nothing), the burst is the longest step
    for r, s in zip(recs, truth["stamps"]):
        assert r["jitter_pct"] == pytest.approx(100 * s["jitter_of_kept_steps"], abs=2.0)
        assert r["longest_step"] == pytest.approx(s["max_step_over_nominal"], abs=0.02)
    planted = [(e["effect"], e["joint"]) for e in truth["effects"]]
    assert _named(res)[:1] == planted
    assert res["verdict"] == truth["expected_verdict"]


def test_a_jittered_csv_log_names_the_planted_effect(tmp_path):
    truth, res = _jittered(tmp_path)
    _check_jittered(truth, res)


@pytest.mark.heavy  # two diagnoses: ~100 s on 2 cores
def test_a_jittered_csv_log_gives_its_uniform_twins_diagnosis(tmp_path):
    truth, res = _jittered(tmp_path)
    folder, ttruth = RL.make_reallog_case(tmp_path / "twin", "jitter_twin", seed=SEEDS["jitter_twin"], small=True)
    assert ttruth["effects"] == truth["effects"]
    twin = _diagnose(folder, tmp_path / "run_twin")
    assert not any(twin["conditioning"][f"traj{i}_position"]["sampling"]["resampled"] for i in range(3))
    _check_jittered(truth, res)
    assert _named(res) == _named(twin)
    assert res["verdict"] == twin["verdict"]
    # the same effect explains both: what remains of each gap lies within its own noise
    for r in (res, twin):
        assert not r["remaining_significant"]
