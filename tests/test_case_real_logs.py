"""A case for a real robot: case.yaml reduces the robot to the joints the logs drive (checked against
Pinocchio's reduced model), `case init` copies every file the robot needs and takes several logs of
one run, and there is one UFF58 reader."""

from __future__ import annotations

import pathlib
import sys

import numpy as np
import pinocchio as pin
import pytest
import yaml

import jflex
from jflex.gap import load_case

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "gap"))
from independent import robots as R  # noqa: E402


def _log(path, t, cols):
    lines = [",".join(["t"] + list(cols))]
    lines += [",".join([f"{t[k]:.12g}"] + [f"{cols[c][k]:.12g}" for c in cols]) for k in range(t.size)]
    path.write_text("\n".join(lines) + "\n")


def _two_joint_logs(folder, n=200):
    t = np.arange(n) * 0.01
    q = np.column_stack([np.sin(t), 0.5 * np.cos(2 * t)])
    _log(folder / "pos.csv", t, {"joint1_position": q[:, 0], "joint2_position": q[:, 1]})
    _log(folder / "eff.csv", t, {"joint1_effort": 3 * q[:, 0] + 1, "joint2_effort": 2 * q[:, 1] - 1})
    return t, q


@pytest.mark.parametrize("via", ["urdf", "yaml"])
def test_case_reduces_the_robot_as_pinocchio_does(tmp_path, via):
    (tmp_path / "arm3.urdf").write_text(R.ARM3_URDF)
    if via == "yaml":
        (tmp_path / "arm3.yaml").write_text("urdf: arm3.urdf\n")
    _two_joint_logs(tmp_path)
    cols = {"time": "t", "position": {"joint1": "joint1_position", "joint2": "joint2_position"},
            "torque": {"joint1": "joint1_effort", "joint2": "joint2_effort"}}
    entry = {"kind": "torque", "file": ["pos.csv", "eff.csv"], "split": "train", "columns": cols}
    cfg = {"robot": {"file": f"arm3.{via}", "joints": ["joint1", "joint2"], "lock": {"joint3": -0.4}},
           "datasets": [entry, dict(entry, split="validation", name="v")]}
    (tmp_path / "case.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    case = load_case(tmp_path)
    assert case.robot.joint_names == ("joint1", "joint2")
    from jflex.gap.report._report import robot_name

    assert robot_name(case) == "arm3"  # the report title names the robot (the URDF name or the YAML stem)
    # the reduced model's inverse dynamics equal Pinocchio's, joint3 locked at -0.4 rad
    full = pin.buildModelFromXML(R.ARM3_URDF)
    red = pin.buildReducedModel(full, [full.getJointId("joint3")], np.array([0.0, 0.0, -0.4]))
    data = red.createData()
    rng = np.random.default_rng(0)
    for _ in range(3):
        q, qd, qdd = rng.normal(size=(3, 2))
        np.testing.assert_allclose(np.asarray(jflex.rnea(case.robot, q, qd, qdd)), pin.rnea(red, data, q, qd, qdd),
                                   rtol=1e-9, atol=1e-9)
    # an unknown joint in the reduction names the field
    cfg["robot"]["joints"] = ["joint1", "elbow"]
    (tmp_path / "case.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    with pytest.raises(jflex.ConfigError, match=r"field 'robot'.*elbow"):
        load_case(tmp_path)


def test_case_init_copies_the_urdf_a_robot_yaml_names_and_merges_logs(tmp_path):
    robots = tmp_path / "robots"
    (robots / "urdf").mkdir(parents=True)
    (robots / "urdf" / "arm3.urdf").write_text(R.ARM3_URDF)
    (robots / "arm3.yaml").write_text("urdf: urdf/arm3.urdf\n")
    logs = tmp_path / "logs"
    logs.mkdir()
    t, q = _two_joint_logs(logs)
    out = tmp_path / "case"
    # as a user types it: jflex case init ROBOT LOG1 LOG2 --out CASE
    from jflex.cli import main

    assert main(["--no-cache", "case", "init", str(robots / "arm3.yaml"), str(logs / "pos.csv"), str(logs / "eff.csv"),
                 "--out", str(out)]) == 0
    p = out / "case.yaml"
    cfg = yaml.safe_load(p.read_text())
    # the robot YAML and its URDF are in the case, the copy pointing at the URDF beside it
    assert (out / "arm3.urdf").read_text() == R.ARM3_URDF
    assert yaml.safe_load((out / "arm3.yaml").read_text())["urdf"] == "arm3.urdf"
    # the logs drive joints 1 and 2: the robot is reduced to them
    assert cfg["robot"] == {"file": "arm3.yaml", "joints": ["joint1", "joint2"]}
    d = cfg["datasets"][0]
    assert d["file"] == ["pos.csv", "eff.csv"] and (out / "pos.csv").is_file() and (out / "eff.csv").is_file()
    cfg["datasets"].append(dict(d, split="validation", name="v"))
    (out / "case.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    case = load_case(out)
    a = case.datasets[0].arrays
    np.testing.assert_allclose(a["q"], q, atol=1e-11)
    np.testing.assert_allclose(a["tau"], np.column_stack([3 * q[:, 0] + 1, 2 * q[:, 1] - 1]), atol=1e-10)
    assert case.datasets[0].conditioning["merge"]["files"] == ["pos.csv", "eff.csv"]


def test_one_uff58_reader():
    import jflex.data
    import jflex.data._uff
    import jflex.identify

    assert jflex.identify.read_uff58 is jflex.data.read_uff58
    assert jflex.data._uff.uff_arrays is jflex.data.uff_arrays


def test_one_log_held_out_by_time_window(tmp_path):
    # `case init --hold-out 0.3`: the last 30 % of one run is the validation set; the two sets hold
    # exactly the log's samples before and after the split, nothing twice
    from jflex.cli import main

    (tmp_path / "arm3.urdf").write_text(R.ARM3_URDF)
    logs = tmp_path / "logs"
    logs.mkdir()
    t, q = _two_joint_logs(logs, n=400)
    out = tmp_path / "case"
    assert main(["--no-cache", "case", "init", str(tmp_path / "arm3.urdf"), str(logs / "pos.csv"),
                 str(logs / "eff.csv"), "--out", str(out), "--hold-out", "0.3"]) == 0
    case = load_case(out)
    tr, va = (next(d for d in case.datasets if d.split == s) for s in ("train", "validation"))
    split = 0.7 * (t[-1] - t[0])
    np.testing.assert_allclose(tr.arrays["t"], t[t <= split + 1e-9], atol=1e-12)
    np.testing.assert_allclose(va.arrays["t"], t[t >= split - 1e-9], atol=1e-12)
    np.testing.assert_allclose(va.arrays["q"], q[t >= split - 1e-9], atol=1e-11)
    assert tr.conditioning["window_s"][1] == pytest.approx(split)
    # a window the record does not reach is refused, naming the field
    cfg = yaml.safe_load((out / "case.yaml").read_text())
    cfg["datasets"][1]["window"] = [100.0, None]
    (out / "case.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    with pytest.raises(jflex.ConfigError, match=r"datasets\[1\]\.window"):
        load_case(out)
    cfg["datasets"][1]["window"] = [2.0, 1.0]
    (out / "case.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    with pytest.raises(jflex.ConfigError, match="window"):
        load_case(out)
