"""The typed diagnosis result: ``diagnosis.json`` is its serialisation (the same mapping as
``Diagnosis.result``, with a schema version), and the report is written from the stored result
alone, without the problem (no model is evaluated to draw it); a simulation that runs away is
recorded as a failed solve (the same 2-joint tip case: the file compiles its programs once)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from jflex_family import generate as G
from jflex.gap import diagnose, load_case
from jflex.gap.response import _response as R
from jflex.gap._result import SCHEMA_VERSION, CandidateResult
from jflex.gap.report._report import write_report

from test_gap_response import TIP_NOISE, _rewrite


@pytest.fixture(scope="module")
def tip_diagnosis(tmp_path_factory):
    # torque training sets, a tool-position validation set: the report's response figure needs the
    # simulated tip series the diagnosis stored
    folder = G.torque_case(tmp_path_factory.mktemp("result") / "tip", "planar2", [], seed=1, n_train=1, n_val=1,
                           tip_noise=TIP_NOISE)
    return diagnose(folder)


def test_diagnosis_round_trips_through_json(tip_diagnosis):
    d = tip_diagnosis
    back = json.loads(d.to_json())
    assert back == json.loads(json.dumps(d.result))
    assert list(back)[-1] == "schema_version" and back["schema_version"] == SCHEMA_VERSION
    assert list(back) == list(d.as_dict())
    # the typed fields are what the mapping holds
    assert back["verdict"] == d.verdict and back["gap_before"] == d.gap_before
    assert back["noise_floor_per_dataset"] == d.floor.per_dataset and back["noise_floor_failed"] == d.floor.failed
    assert all(isinstance(e, CandidateResult) for e in d.ranking + d.selected)
    assert back["ranking"] == [json.loads(json.dumps(e.as_dict())) for e in d.ranking]
    assert d.result is d.result  # made once: a note added to it stays
    with pytest.raises(dataclasses.FrozenInstanceError):
        d.verdict = "explained"


def test_report_is_written_without_the_problem(tip_diagnosis, tmp_path):
    d = dataclasses.replace(tip_diagnosis, problem=None, nominal=None, final=None)
    md = write_report(d, tmp_path / "out").read_text()
    written = json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    assert "plot_error" not in written, written.get("plot_error")
    names = [s.name for s in d.series.responses]
    assert names and all((tmp_path / "out" / f"response_{n}.png").is_file() for n in names)
    assert all(f"(response_{n}.png)" in md for n in names)
    assert (tmp_path / "out" / "report.html").is_file() and (tmp_path / "out" / "waterfall.png").is_file()


def test_failed_solves_are_recorded(tmp_path):
    # torques a thousand times too large over the record's last fifth: the simulation runs away;
    # its samples beyond the 1000 % cap are counted in diagnosis.json and listed in the report
    # (a runaway from mid-record says the same, but its solver steps take ten seconds more)
    from jflex.gap.report._report import markdown

    folder = G.torque_case(tmp_path / "fail", "planar2", [], seed=1, n_train=1, n_val=1, tip_noise=TIP_NOISE)
    _rewrite(folder, lambda z: z["tau"].__setitem__(slice(len(z["tau"]) * 4 // 5, None), z["tau"][len(z["tau"]) * 4 // 5:] * 1e3))
    r = diagnose(folder, max_effects=0, prune=0).result
    f = r["failed_solves"]
    assert [(e["model"], e["dataset"]) for e in f] == [("nominal", "tip1")] and 0 < f[0]["samples"] <= f[0]["of"] == 300
    assert "Failed or diverged simulations" in markdown(r, [])
    # the runaway residual is no noise: the floor comes from the record's own fourth difference
    # and matches the planted tip noise (the residual's second difference would count the runaway)
    d = next(d for d in load_case(folder).datasets if d.kind == "response")
    s = R.response_set(load_case(folder).robot, d, "tool")
    expected = np.sqrt(np.mean((TIP_NOISE / s.scale) ** 2)) * 100
    assert r["noise_floor_source"] == {"tip1": "record fourth difference"}
    assert 0.7 * expected < r["noise_floor"] < 1.3 * expected
    # repeated records, when there are, set the floor
    rng = np.random.default_rng(0)
    _rewrite(folder, lambda z: z.update(y_repeats=z["y"][None] + 2 * TIP_NOISE * rng.standard_normal((4,) + z["y"].shape)))
    r = diagnose(folder, max_effects=0, prune=0).result
    assert r["noise_floor_source"] == {"tip1": "y_repeats"}
    assert 1.6 * expected < r["noise_floor"] < 2.4 * expected
