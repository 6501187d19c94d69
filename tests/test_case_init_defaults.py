"""`jflex case init` on real logs: the nominal friction it writes by default, logs without a time
column (`--rate`), several runs with one header, what it refuses before writing anything (an
`--out` that is a file, a `--hold-out` that load_case would refuse), a case.yaml without YAML
anchors, and a URDF whose cycle cuts links off the root."""

from __future__ import annotations

import pathlib
import sys

import numpy as np
import pytest
import yaml

import jflex
from jflex.gap import load_case
from jflex.gap.case._init import case_init

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "gap"))
from independent import robots as R  # noqa: E402

JOINTS = ["joint1", "joint2", "joint3"]


def _log(path, n=300, dt=0.01, time=True, header=None):
    rng = np.random.default_rng(len(path.name))
    t = np.arange(n) * dt
    q = np.column_stack([np.sin(t + k) for k in range(3)])
    tau = np.column_stack([np.cos(2 * t + k) for k in range(3)]) + 0.01 * rng.normal(size=(n, 3))
    head = header or (["t"] if time else []) + ["q1", "q2", "q3", "tau1", "tau2", "tau3"]
    rows = [np.concatenate([[t[k]] if time else [], q[k], tau[k]]) for k in range(n)]
    path.write_text(",".join(head) + "\n" + "\n".join(",".join(f"{v:.9g}" for v in r) for r in rows) + "\n")
    return t, q, tau


@pytest.fixture
def arm(tmp_path):
    (tmp_path / "arm3.urdf").write_text(R.ARM3_URDF)
    return tmp_path / "arm3.urdf"


def test_default_case_holds_viscous_and_coulomb_friction_at_every_joint(tmp_path, arm):
    _log(tmp_path / "log.csv")
    path = case_init(arm, tmp_path / "log.csv", tmp_path / "case", hold_out=0.3)
    text = path.read_text()
    cfg = yaml.safe_load(text)
    assert cfg["nominal_effects"] == [{"effect": "viscous_friction", "joint": "all"},
                                      {"effect": "coulomb_friction", "joint": "all"}]
    assert "# nominal_effects: viscous and Coulomb friction" in text  # the comment says so, and how to drop it
    case = load_case(path)
    got = {(e["effect"], j) for e in case.nominal_effects for j in e["joints"]}
    assert got == {(e, j) for e in ("viscous_friction", "coulomb_friction") for j in JOINTS}


def test_demo_case_keeps_its_own_nominal_model():
    # the demo's data hide Coulomb friction at one joint: its case must not state it as nominal
    demo = pathlib.Path(jflex.__file__).parent / "data" / "demo_case" / "case.yaml"
    cfg = yaml.safe_load(demo.read_text())
    assert [e["effect"] for e in cfg["nominal_effects"]] == ["viscous_friction"]


def test_rate_for_a_log_without_time_column(tmp_path, arm):
    t, q, tau = _log(tmp_path / "log.csv", dt=0.004, time=False)
    with pytest.raises(jflex.ConfigError, match="field 'hold_out': needs the time column"):
        case_init(arm, tmp_path / "log.csv", tmp_path / "no", hold_out=0.3)
    assert not (tmp_path / "no").exists()  # refused before anything is written
    path = case_init(arm, tmp_path / "log.csv", tmp_path / "case", hold_out=0.3, rate=250.0)
    cfg = yaml.safe_load(path.read_text())
    assert cfg["datasets"][0]["rate"] == 250.0 and "time" not in cfg["datasets"][0]["columns"]
    case = load_case(path)
    tr = case.split("train")[0].arrays
    np.testing.assert_allclose(tr["t"], t[t <= 0.7 * t[-1] + 1e-9], atol=1e-12)
    np.testing.assert_allclose(tr["q"], q[: tr["t"].size], atol=1e-8)
    with pytest.raises(jflex.ConfigError, match="field 'rate'"):
        case_init(arm, tmp_path / "log.csv", tmp_path / "neg", rate=-5.0)
    _log(tmp_path / "timed.csv")
    with pytest.raises(jflex.ConfigError, match="field 'rate': the log has a time column"):
        case_init(arm, tmp_path / "timed.csv", tmp_path / "both", rate=100.0)


def test_rate_and_time_column_together_refused_at_load(tmp_path, arm):
    _log(tmp_path / "log.csv")
    path = case_init(arm, tmp_path / "log.csv", tmp_path, hold_out=0.3)
    cfg = yaml.safe_load(path.read_text())
    cfg["datasets"][0]["rate"] = 100.0
    path.write_text(yaml.safe_dump(cfg))
    with pytest.raises(jflex.ConfigError, match=r"datasets\[0\]\.rate.*either columns.time or rate"):
        load_case(path)


def test_runs_with_one_header_are_separate_data_sets(tmp_path, arm):
    for k in range(3):
        _log(tmp_path / f"run{k}.csv", n=200 + 10 * k)
    path = case_init(arm, [tmp_path / f"run{k}.csv" for k in range(3)], tmp_path / "case")
    cfg = yaml.safe_load(path.read_text())
    assert [(d["file"], d["split"], d["name"]) for d in cfg["datasets"]] == [
        ("run0.csv", "train", "run0"), ("run1.csv", "train", "run1"), ("run2.csv", "validation", "run2")]
    case = load_case(path)
    assert [d.arrays["t"].size for d in case.datasets] == [200, 210, 220]
    both = case_init(arm, [tmp_path / f"run{k}.csv" for k in range(2)], tmp_path / "split", hold_out=0.25)
    names = [(d["name"], d["split"]) for d in yaml.safe_load(both.read_text())["datasets"]]
    assert names == [("run0_train", "train"), ("run0_validation", "validation"),
                     ("run1_train", "train"), ("run1_validation", "validation")]
    assert len(load_case(both).datasets) == 4


def test_out_that_is_a_file_is_a_named_error(tmp_path, arm):
    _log(tmp_path / "log.csv")
    (tmp_path / "taken").write_text("x")
    with pytest.raises(jflex.ConfigError, match="field 'out': exists and is not a folder"):
        case_init(arm, tmp_path / "log.csv", tmp_path / "taken")
    from jflex.cli import main

    assert main(["case", "init", str(arm), str(tmp_path / "log.csv"), "--out", str(tmp_path / "taken")]) == 2


def test_cli_error_prefix_once(tmp_path, arm, capsys):
    from jflex.cli import main

    _log(tmp_path / "log.csv", time=False)
    assert main(["case", "init", str(arm), str(tmp_path / "log.csv"), "--out", str(tmp_path / "c"),
                 "--hold-out", "0.3"]) == 2
    err = capsys.readouterr().err
    assert err.count("case init") == 1 and "field 'hold_out'" in err


def test_no_yaml_anchors_train_and_validation_maps_are_separate(tmp_path, arm):
    _log(tmp_path / "log.csv")
    path = case_init(arm, tmp_path / "log.csv", tmp_path, hold_out=0.3)
    text = path.read_text()
    assert "&id" not in text and "*id" not in text
    cfg = yaml.safe_load(text)
    cfg["datasets"][0]["columns"]["torque"]["joint1"] = "tau2"
    assert cfg["datasets"][1]["columns"]["torque"]["joint1"] == "tau1"


@pytest.mark.parametrize("frac", [1e-9, 0.999999, 0.05])
def test_hold_out_refused_at_init_by_the_load_rule(tmp_path, arm, frac):
    _log(tmp_path / "log.csv", n=200)
    with pytest.raises(jflex.ConfigError, match=r"field 'hold_out'.*at least 20 samples on each side"):
        case_init(arm, tmp_path / "log.csv", tmp_path / "c", hold_out=frac)
    assert not (tmp_path / "c" / "case.yaml").exists()
    # the smallest fraction it accepts loads
    load_case(case_init(arm, tmp_path / "log.csv", tmp_path / "ok", hold_out=0.1))


@pytest.mark.parametrize("frac", [0.0, 1.0, -0.2, float("nan")])
def test_hold_out_outside_the_unit_interval(tmp_path, arm, frac):
    _log(tmp_path / "log.csv")
    with pytest.raises(jflex.ConfigError, match=r"field 'hold_out': expected a fraction in \(0, 1\)"):
        case_init(arm, tmp_path / "log.csv", tmp_path / "c", hold_out=frac)


def test_negative_max_effects_refused_on_the_command_line(tmp_path, capsys):
    from jflex.cli import main

    assert main(["diagnose", str(tmp_path), "--max-effects", "-1"]) == 2
    assert "--max-effects: expected an integer >= 0" in capsys.readouterr().err


CYCLE = """<robot name="c">
  <link name="base"/><link name="a"/><link name="b"/><link name="c"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="b"/><child link="c"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="c"/><child link="b"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>"""


def test_urdf_cycle_cut_off_from_the_root_is_refused(tmp_path):
    (tmp_path / "c.urdf").write_text(CYCLE)
    with pytest.raises(jflex.URDFError, match=r"links \['b', 'c'\] are not reached from the root link 'base'"):
        jflex.load_urdf(tmp_path / "c.urdf")
    _log(tmp_path / "log.csv")
    with pytest.raises(jflex.JFlexError, match="not reached from the root"):
        case_init(tmp_path / "c.urdf", tmp_path / "log.csv", tmp_path / "case")
