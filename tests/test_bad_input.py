"""Bad input gets a jflex error that names the link, joint or field - never a deep traceback."""

import re

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings, strategies as st

import jflex

GOOD_URDF = """<robot name="r">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0 0 0.1"/><mass value="1.0"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <link name="l2"><inertial><mass value="2.0"/>
    <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>
  <link name="tool"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="2"/></joint>
  <joint name="j2" type="prismatic"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.5" rpy="0 1.57 0"/>
    <axis xyz="1 0 0"/><limit lower="0" upper="0.4" effort="100" velocity="1"/></joint>
  <joint name="flange" type="fixed"><parent link="l2"/><child link="tool"/><origin xyz="0 0 0.2"/></joint>
</robot>"""


def test_good_urdf_loads():
    r = jflex.from_urdf_string(GOOD_URDF)
    assert r.joint_names == ("j1", "j2") and r.frame_names == ("tool",)


@pytest.mark.parametrize(
    "old,new,pattern",
    [
        ('<inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/>', "", "l2.*no <inertia>"),
        ('ixx="0.02" ixy="0" ixz="0" iyy="0.02"', 'ixx="0.02" ixy="0.5" ixz="0" iyy="0.02"', "l2.*positive semi-definite"),  # strict=True: by default a warning
        ('<mass value="2.0"/>', '<mass value="-2.0"/>', "l2.*mass"),
        ('type="prismatic"', 'type="floating"', "j2.*unknown or unsupported joint type 'floating'"),
        ('<parent link="l1"/>', '<parent link="l9"/>', "j2.*parent link 'l9' is not defined"),
        ('<axis xyz="1 0 0"/>', '<axis xyz="1 0"/>', "j2.*axis"),
        ('lower="0" upper="0.4"', 'lower="1" upper="0.4"', "j2.*lower"),
    ],
)
def test_urdf_errors_name_the_culprit(old, new, pattern):
    assert old in GOOD_URDF
    with pytest.raises(jflex.URDFError, match=pattern):
        jflex.from_urdf_string(GOOD_URDF.replace(old, new, 1), strict=True)


def test_urdf_nan_or_inf_limits():
    with pytest.raises(jflex.URDFError, match="j1.*velocity"):
        jflex.from_urdf_string(GOOD_URDF.replace('velocity="2"', 'velocity="nan"'))
    r = jflex.from_urdf_string(GOOD_URDF.replace('effort="10"', 'effort="inf"'))
    assert np.isinf(r.effort_limit[0])


def test_missing_urdf_file(tmp_path):
    with pytest.raises(jflex.URDFError, match="not found"):
        jflex.load_urdf(tmp_path / "nope.urdf")


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cut=st.integers(0, len(GOOD_URDF)), junk=st.text(max_size=12), pos=st.integers(0, len(GOOD_URDF)))
def test_urdf_fuzz_never_escapes(cut, junk, pos):
    """Truncations and insertions either load or raise a URDFError - nothing else."""
    for text in (GOOD_URDF[:cut], GOOD_URDF[:pos] + junk + GOOD_URDF[pos:]):
        try:
            jflex.from_urdf_string(text)
        except jflex.URDFError as exc:
            assert str(exc)


GOOD_DH = {
    "name": "arm",
    "dh": {"convention": "modified", "angles": "deg", "rows": [[0, 0, 0.5, 0], [90, 0.2, 0, 0]], "tool": [0, 0.3, 0, 0]},
    "links": [{"mass": 1.0, "com": [0, 0, 0.1], "inertia": [0.1, 0, 0.1, 0, 0, 0.1]}] * 2,
    "limits": {"lower": [-170, -90], "upper": [170, 90], "angles": "deg"},
}


def test_good_dh_config_loads():
    r = jflex.robot_from_config(GOOD_DH)
    np.testing.assert_allclose(r.upper, np.deg2rad([170, 90]))


@pytest.mark.parametrize(
    "mutate,pattern",
    [
        (lambda c: c["dh"]["rows"].__setitem__(1, [90, 0.2, 0]), r"dh\.rows\[1\]: expected 4 columns"),
        (lambda c: c["dh"].__setitem__("convention", "craig"), r"dh\.convention"),
        (lambda c: c["dh"].__setitem__("angles", "grad"), r"dh\.angles"),
        (lambda c: c.__setitem__("links", c["links"][:1]), r"links: expected a list of 2"),
        (lambda c: c["links"].__setitem__(0, {"mass": -1.0}), r"links\[0\]\.mass"),
        (lambda c: c["links"].__setitem__(0, {"mass": 1.0, "inertia": [1, 5, 1, 0, 0, 1]}), r"inertias\[0\]|positive"),
        (lambda c: c.__setitem__("gravity", [0, 0]), r"gravity"),
        (lambda c: c.__setitem__("colour", "red"), r"unknown keys \['colour'\]"),
        (lambda c: c["limits"].__setitem__("lower", [0]), r"limits\.lower"),
    ],
)
def test_dh_config_errors_name_the_field(mutate, pattern):
    cfg = yaml.safe_load(yaml.safe_dump(GOOD_DH))
    mutate(cfg)
    with pytest.raises(jflex.ConfigError, match=pattern):
        jflex.robot_from_config(cfg)


yaml_values = st.recursive(
    st.none() | st.booleans() | st.integers(-5, 5) | st.floats(allow_nan=True) | st.text(max_size=5),
    lambda children: st.lists(children, max_size=5) | st.dictionaries(st.text(max_size=6), children, max_size=4),
    max_leaves=12,
)


@settings(max_examples=80, deadline=None)
@given(key=st.sampled_from(["dh", "links", "limits", "gravity", "joint_names", "urdf"]), value=yaml_values)
def test_config_fuzz_never_escapes(key, value):
    cfg = yaml.safe_load(yaml.safe_dump(GOOD_DH))
    cfg[key] = value
    try:
        jflex.robot_from_config(cfg)
    except jflex.JFlexError as exc:
        assert str(exc)


@settings(max_examples=40, deadline=None)
@given(row=st.integers(0, 1), col=st.integers(0, 3), value=yaml_values)
def test_dh_row_fuzz_never_escapes(row, col, value):
    cfg = yaml.safe_load(yaml.safe_dump(GOOD_DH))
    cfg["dh"]["rows"][row][col] = value
    try:
        jflex.robot_from_config(cfg)
    except jflex.JFlexError as exc:
        assert str(exc)


def test_dh_table_wrong_columns():
    with pytest.raises(jflex.ConfigError, match=r"4 columns"):
        jflex.from_dh(np.zeros((3, 5)))


def test_q_of_wrong_length_names_the_joints():
    r = jflex.robot_from_config(GOOD_DH)
    with pytest.raises(jflex.ShapeError, match=re.escape("q must have shape (2,)")):
        jflex.rnea(r, np.zeros(3), np.zeros(2), np.zeros(2))
    with pytest.raises(jflex.ShapeError, match="qd must have shape"):
        jflex.crba(r, np.zeros(2)) is not None and jflex.rnea(r, np.zeros(2), np.zeros(4), np.zeros(2))


def test_unknown_robot_name():
    with pytest.raises(jflex.ConfigError, match="unknown robot 'nope'"):
        jflex.load_robot("nope")
