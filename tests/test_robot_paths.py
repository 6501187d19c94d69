"""Robot names and robot-file paths: a robot YAML inside a case reads only files inside the case
folder (unless the caller allows more); a name too long, a NUL byte, a joint listed twice get a
ConfigError naming the field; a robot that needs an optional package names the extra to install."""

from __future__ import annotations

import pathlib

import pytest

import jflex
from jflex import _config

URDF = """<robot name="r">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0 0 0.1"/><mass value="1.0"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <link name="l2"><inertial><mass value="2.0"/>
    <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="2"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.5"/>
    <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="10" velocity="2"/></joint>
</robot>"""


def _case(folder: pathlib.Path, urdf_field: str) -> pathlib.Path:
    """A case folder whose robot.yaml names ``urdf_field``; only the robot matters here."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "robot.yaml").write_text(f"urdf: {urdf_field!r}\n")
    (folder / "case.yaml").write_text("robot: robot.yaml\ndatasets: []\n")
    return folder


def _robot_of(folder, **kw):
    from jflex.gap.case._case import _load_robot

    return _load_robot("robot.yaml", folder, folder / "case.yaml", kw.get("allow_outside", False))


def test_robot_yaml_urdf_inside_the_case_loads(tmp_path):
    case = _case(tmp_path / "case", "urdf/arm.urdf")
    (case / "urdf").mkdir()
    (case / "urdf" / "arm.urdf").write_text(URDF)
    assert _robot_of(case).joint_names == ("j1", "j2")
    # the same through load_robot with the folder it must stay in
    assert jflex.load_robot(case / "robot.yaml", within=case).nq == 2


@pytest.mark.parametrize("given", ["../outside.urdf", "sub/../../outside.urdf", "ABSOLUTE"])
def test_robot_yaml_urdf_outside_the_case_refused(tmp_path, given):
    outside = tmp_path / "outside.urdf"
    outside.write_text(URDF)
    given = str(outside) if given == "ABSOLUTE" else given
    case = _case(tmp_path / "case", given)
    (case / "sub").mkdir()
    with pytest.raises(jflex.ConfigError) as exc:
        _robot_of(case)
    msg = str(exc.value)
    assert "field 'robot'" in msg and ".urdf" in msg and "allow_outside" in msg, msg
    assert ("absolute path" in msg) == (given == str(outside)), msg
    # allowed out on request, as load_case(allow_outside=True) does
    assert _robot_of(case, allow_outside=True).nq == 2


def test_robot_yaml_urdf_etc_passwd_not_opened(tmp_path, monkeypatch):
    case = _case(tmp_path / "case", "/etc/passwd")
    opened = []
    real = _config.load_urdf
    monkeypatch.setattr(_config, "load_urdf", lambda path, **kw: opened.append(path) or real(path, **kw))
    with pytest.raises(jflex.ConfigError, match="absolute path '/etc/passwd'"):
        _robot_of(case)
    assert opened == []


def test_symlink_out_of_the_case_refused(tmp_path):
    outside = tmp_path / "outside.urdf"
    outside.write_text(URDF)
    case = _case(tmp_path / "case", "arm.urdf")
    (case / "arm.urdf").symlink_to(outside)
    with pytest.raises(jflex.ConfigError, match="resolves outside"):
        _robot_of(case)


@pytest.mark.parametrize("spec,pattern", [
    ("x" * 5000, r"robot: 'x{60}'\.\.\. \(5000 characters\) is too long"),
    ("arm\x00.yaml", "robot: .* contains a NUL byte"),
    ("/tmp/" + "y" * 300 + ".yaml", "is too long"),
])
def test_bad_robot_names_name_the_field(spec, pattern):
    with pytest.raises(jflex.ConfigError, match=pattern):
        jflex.load_robot(spec)


def test_bad_urdf_field_in_robot_yaml(tmp_path):
    f = tmp_path / "r.yaml"
    f.write_text('urdf: "a\\0b.urdf"\n')
    with pytest.raises(jflex.ConfigError, match=r"r\.yaml\.urdf: .*NUL byte"):
        jflex.load_robot(f)


def test_load_yaml_of_unreadable_paths():
    for bad in ("z" * 5000 + ".yaml", "a\x00b.yaml"):
        with pytest.raises(jflex.ConfigError, match="cannot read this config file"):
            jflex.load_yaml(bad)


def test_duplicate_joint_names_refused(tmp_path):
    (tmp_path / "arm.urdf").write_text(URDF)
    f = tmp_path / "r.yaml"
    f.write_text("urdf: arm.urdf\njoints: [j1, j2, j1]\n")
    with pytest.raises(jflex.ConfigError, match=r"r\.yaml\.joints: joint 'j1' is listed twice"):
        jflex.load_robot(f)
    f.write_text("dh: {rows: [[0, 0, 0, 0], [0, 1, 0, 0]]}\njoint_names: [a, a]\n")
    with pytest.raises(jflex.ConfigError, match=r"r\.yaml\.joint_names: joint 'a' is listed twice"):
        jflex.load_robot(f)


def test_panda_without_example_robot_data_names_the_extra(monkeypatch):
    import importlib.metadata as md

    def missing(name):
        raise md.PackageNotFoundError(name)

    monkeypatch.setattr(md, "files", missing)
    monkeypatch.setattr(md, "distribution", missing)
    with pytest.raises(jflex.ConfigError) as exc:
        jflex.load_robot("panda")
    msg = str(exc.value)
    assert "example-robot-data" in msg and 'pip install "jflex[robots]"' in msg, msg
    # and the extra exists in the project's metadata
    import tomllib

    extras = tomllib.loads((pathlib.Path(__file__).resolve().parents[1] / "pyproject.toml").read_text())
    assert any("example-robot-data" in r for r in extras["project"]["optional-dependencies"]["robots"])


@pytest.mark.parametrize("robot", ["arm\x00.yaml", "r" * 5000, "r" * 5000 + ".urdf"])
def test_case_robot_field_nul_or_too_long(tmp_path, robot):
    from jflex.gap.case._case import _load_robot

    with pytest.raises(jflex.ConfigError, match="field 'robot'"):
        _load_robot(robot, tmp_path, tmp_path / "case.yaml", False)


def test_info_with_a_5000_character_name_is_a_clean_error(capsys):
    from jflex.cli import main

    assert main(["info", "x" * 5000]) == 2
    err = capsys.readouterr().err
    assert "too long" in err and len(err) < 400, err


@pytest.mark.parametrize("given", ["../outside.urdf", "ABSOLUTE"])
def test_reduced_robot_yaml_urdf_outside_the_case_refused(tmp_path, given):
    # the `robot: {file: robot.yaml, joints: [...]}` form reads the URDF its YAML names under the
    # same rule as the plain `robot: robot.yaml`
    from types import SimpleNamespace

    from jflex.gap.case._case import _load_reduced_robot

    outside = tmp_path / "outside.urdf"
    outside.write_text(URDF)
    case = _case(tmp_path / "case", str(outside) if given == "ABSOLUTE" else given)
    spec = SimpleNamespace(file="robot.yaml", joints=["j1"], lock=None)
    with pytest.raises(jflex.ConfigError, match="allow_outside"):
        _load_reduced_robot(spec, case, case / "case.yaml", False)
    assert _load_reduced_robot(spec, case, case / "case.yaml", True).joint_names == ("j1",)
