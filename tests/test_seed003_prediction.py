"""experiments/seed003_prediction.py on a small setting, and the schemas of the experiments that
share its model of the thesis' robots (identify_seed003, seed003_prediction)."""

from __future__ import annotations

import importlib.util
import itertools
import json
import pathlib
import sys

import numpy as np
import pytest
import yaml

import jflex

ROOT = pathlib.Path(__file__).resolve().parent.parent

# the thesis' robot model is a sibling module of the experiments that use it
sys.path.insert(0, str(ROOT / "experiments"))
from _machining_robot import MachiningRobot  # noqa: E402


def _experiment(name):
    spec = importlib.util.spec_from_file_location(f"_exp_{name}", ROOT / "experiments" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # pydantic resolves the schemas' annotations through it
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("name, schema, bad", [
    ("identify_seed003", "IdentifySeed003Config", [("max_steps", 0), ("identify_on", [3]), ("weights", {"frequency": -1.0})]),
    ("seed003_prediction", "PredictionConfig", [("splits", [[1, 4]]), ("max_steps", "60"), ("nonsense", 1)]),
])
def test_seed003_experiment_schemas(tmp_path, name, schema, bad):
    mod = _experiment(name)
    shipped = ROOT / "configs" / f"{name}.yaml"
    seen = []
    jflex.experiment_cli(name, shipped, lambda cfg, d: seen.append(cfg) or {}, ["--out", str(tmp_path / "ok")],
                         schema=getattr(mod, schema))
    assert len(seen) == 1
    for field, value in bad:
        cfg = yaml.safe_load(shipped.read_text())
        cfg[field] = value
        path = tmp_path / "bad.yaml"
        path.write_text(yaml.safe_dump(cfg))
        with pytest.raises(jflex.ConfigError, match=rf"bad\.yaml: field '{field}"):
            jflex.experiment_cli(name, path, lambda cfg, d: seen.append(cfg) or {}, ["--out", str(tmp_path / "bad")],
                                 schema=getattr(mod, schema))
    assert len(seen) == 1  # run never saw a bad config


def _run(tmp_path, diagnose: bool, max_steps: int):
    cfg = dict(hold="actuated", max_steps=max_steps, diagnose=diagnose, splits=[[1]],
               robots=[dict(config="seed003/kuka_kr90.yaml", extra_modes_configuration1_Hz=[19.2])])
    path = tmp_path / "cfg.yaml"
    path.write_text(yaml.safe_dump(cfg))
    _experiment("seed003_prediction").main([str(path), "--out", str(tmp_path / "run")])
    return json.loads((tmp_path / "run" / "results.json").read_text())["robots"]["kuka_kr90"]


@pytest.fixture(scope="module")
def kr90_run(tmp_path_factory):
    # one run serves both tests below: the K, C refit variant is fitted and evaluated the same
    # way with or without the diagnosis beside it (experiments/seed003_prediction.py builds it
    # before, and independently of, the diagnosed one), so a second run without it adds nothing
    return _run(tmp_path_factory.mktemp("kr90"), diagnose=True, max_steps=30)


@pytest.mark.experiments  # a run of the experiment (1-2 min): CI's step after the suite
def test_prediction_kc_refit_pairs_rows_by_shape(kr90_run):
    """K, C fitted on configuration 1 of the KR90: the fitted rows reproduce Table 4.6's Exp.
    values (6 parameters, 6 numbers), the rows of configurations 2-3 are paired one-to-one with
    the model modes of highest total MAC to configuration 1, and the thesis rows carry their
    source (values typed from Table 4.6)."""
    out = kr90_run
    sp = out["splits"][0]
    m = sp["models"]["K,C refit"]
    f = np.asarray(m["frequency_Hz"])
    # the thesis' Table 4.6, configuration 1, Exp. column, rows 1-3
    np.testing.assert_allclose(f[0], [10.0, 11.0, 23.7], rtol=0.01)
    rob = MachiningRobot.from_config(ROOT / "configs" / "seed003" / "kuka_kr90.yaml")
    model = rob.configured_model(np.asarray(m["values"]["K_N_m_per_rad"]), np.asarray(m["values"]["C_N_m_s_per_rad"]))[0]
    shapes = [np.asarray(jflex.modal_analysis(model, q, hold="actuated").shape) for q in rob.postures]
    idx = np.asarray(m["mode_index"])
    for k in (1, 2):
        assert sorted(idx[k].tolist()) == [0, 1, 2]
        M = np.asarray(jflex.mac(shapes[0], shapes[k]))
        best = max(itertools.permutations(range(3)), key=lambda p: sum(M[i, p[i]] for i in range(3)))
        assert tuple(idx[k]) == best
    assert sp["predicted_configurations"] == [2, 3]
    row = next(r for r in out["thesis_rows"] if r["configuration"] == 2 and r["row"] == 1)
    assert row["frequency_exp_Hz"] == 20.4 and row["frequency_model_Hz"] == 14.6  # Table 4.6, configuration 2, row 1
    assert "Table 4.6, configuration 2, row 1" in row["source"]


@pytest.mark.experiments  # a run of the experiment (1-2 min): CI's step after the suite
def test_prediction_diagnosed_effect_beats_kc_refit(kr90_run):
    """KR90 fitted on configuration 1 (its fourth EMA mode, 19.2 Hz, included): the diagnosis,
    which sees configuration 1 only, adds an orthogonal compliance, and the model with it predicts
    configurations 2-3 better than the K, C refit does (held-out rows paired by shape)."""
    sp = kr90_run["splits"][0]
    assert [e[0] for e in sp["diagnosis"]["selected"]] == ["orthogonal_compliance"]
    kc = sp["models"]["K,C refit"]["heldout_mean_frequency_error_pct"]
    dg = sp["models"]["K,C + diagnosed"]["heldout_mean_frequency_error_pct"]
    assert dg < kc, (dg, kc)
