"""The typed diagnosis result: ``diagnosis.json`` is its serialisation (the same mapping as
``Diagnosis.result``, with a schema version), and the report is written from the stored result
alone, without the problem (no model is evaluated to draw it)."""

from __future__ import annotations

import dataclasses
import json

import pytest

from jflex_family import generate as G
from jflex.gap import diagnose
from jflex.gap._result import SCHEMA_VERSION, CandidateResult
from jflex.gap.report._report import write_report

TIP_NOISE = 1e-4  # [m]


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
