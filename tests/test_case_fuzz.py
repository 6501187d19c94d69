"""Property test of the case loader (issue 15): mutated case.yaml dicts, NPZ files and URDF texts
either load, with finite arrays, or raise a JFlexError whose message names a field; never a plain
Python exception. Loading only (no diagnosis); a bounded number of examples."""

from __future__ import annotations

import contextlib
import copy
import math
import os
import pathlib
import re
import tempfile
import warnings

import numpy as np
import yaml
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import jflex
from jflex._runs import MAX_YAML_NODES
from jflex.gap import load_case
from test_case_schema import write_case

# the CI runs 60 fixed examples per test; JFLEX_SLOW=1 draws 500 fresh ones
SLOW = os.environ.get("JFLEX_SLOW") == "1"
SETTINGS = settings(max_examples=500 if SLOW else 60, deadline=None, derandomize=not SLOW, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
FIELD = re.compile(r"field '[^']+'")

BASE = {
    "robot": "robot.yaml",
    "tool_frame": "tool",
    "nominal_effects": [
        {"effect": "joint_flexibility", "joint": "all", "stiffness": [3e5, 2e5], "damping": [10.0, 5.0]},
        {"effect": "rotor_inertia", "joint": ["elbow"], "value": 0.01},
        {"effect": "viscous_friction", "joint": 0},
    ],
    "datasets": [{"kind": "torque", "file": "traj0.npz", "split": "train"},
                 {"kind": "torque", "file": "traj1.npz", "split": "validation", "name": "val"}],
    "noise": {"modal_frequency_pct": 1.0},
    "options": {"inertia_prior": 1.0, "refit_inertia": True, "filter_cutoff_hz": "auto", "decimate": 1, "max_effects": 3},
    "notes": "fuzz base",
}
BAD_VALUES = [None, "abc", "", 1.5, -1, 0, 7, 10**30, math.nan, math.inf, -math.inf, True, [], {}, [1, "a"],
              {"x": 1}, "../../etc/passwd", "/etc/passwd", "../other/traj0.npz", "joint9", ["all", "elbow"],
              "traj0.npz", "robot.yaml", "tool", "all", "train", "torque", "frf", [0.1, 0.2], "rad"]


def _paths(x, prefix=()):
    """Every (path, value) of a nested dict/list."""
    out = [(prefix, x)]
    if isinstance(x, dict):
        for k, v in x.items():
            out += _paths(v, prefix + (k,))
    elif isinstance(x, list):
        for i, v in enumerate(x):
            out += _paths(v, prefix + (i,))
    return out


def _mutate(cfg, op, k, value):
    paths = [p for p, _ in _paths(cfg) if p]
    path = paths[k % len(paths)]
    parent = cfg
    for key in path[:-1]:
        parent = parent[key]
    last = path[-1]
    if op == "drop":
        del parent[last]
    elif op == "rename" and isinstance(parent, dict):
        parent[f"{last}x"] = parent.pop(last)
    elif op == "add" and isinstance(parent, dict):
        parent["unexpected"] = value
    else:
        parent[last] = value


@contextlib.contextmanager
def _case_dir():
    with tempfile.TemporaryDirectory() as d:
        yield write_case(pathlib.Path(d) / "case")


def _check(folder):
    """Load: success with finite arrays, or a JFlexError naming a field."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            case = load_case(folder)
    except jflex.JFlexError as exc:
        assert FIELD.search(str(exc)), f"no field named in: {exc}"
        return "error"
    for d in case.datasets:
        for name, a in d.arrays.items():
            if isinstance(a, np.ndarray) and a.dtype.kind in "fc" and name != "zeta":
                assert np.isfinite(a).all(), f"{d.name}.{name} holds NaN/inf"
    for e in case.nominal_effects:
        for key in ("stiffness", "damping", "value"):
            if key in e:
                assert np.isfinite(e[key]).all() and (e[key] >= 0).all()
        if "stiffness" in e:
            assert (e["stiffness"] > 0).all()
    return "ok"


OPS = st.tuples(st.sampled_from(["drop", "rename", "set", "set", "add"]), st.integers(0, 200),
                st.sampled_from(BAD_VALUES))


@SETTINGS
@given(st.lists(OPS, min_size=1, max_size=3))
def test_mutated_case_yaml(ops):
    with _case_dir() as folder:
        (folder.parent / "other").mkdir()
        cfg = copy.deepcopy(BASE)
        for op, k, v in ops:
            _mutate(cfg, op, k, copy.deepcopy(v))
        (folder / "case.yaml").write_text(yaml.safe_dump(cfg, allow_unicode=True))
        _check(folder)


ARRAY_OPS = st.sampled_from(["drop", "nan", "inf", "transpose", "cut_rows", "cut_cols", "add_dim", "strings",
                             "complex", "bool", "empty", "reverse_t", "scalar", "object"])


@SETTINGS
@given(st.lists(st.tuples(ARRAY_OPS, st.sampled_from(["t", "q", "tau", "qd", "qdd", "tau_repeats", "joints"]),
                          st.integers(0, 10**6)), min_size=1, max_size=3))
def test_mutated_npz(ops):
    with _case_dir() as folder:
        z = dict(np.load(folder / "traj0.npz"))
        for op, field, k in ops:
            a = np.asarray(z.get(field, np.zeros((50, 2))))
            if op == "drop":
                z.pop(field, None)
                continue
            if op in ("nan", "inf") and a.size and a.dtype.kind == "f":
                a = a.copy()
                a.flat[k % a.size] = np.nan if op == "nan" else np.inf
            elif op == "transpose":
                a = a.T
            elif op == "cut_rows" and a.ndim:
                a = a[: k % max(len(a), 1)]
            elif op == "cut_cols" and a.ndim == 2:
                a = a[:, :1]
            elif op == "add_dim":
                a = a[None]
            elif op == "strings":
                a = a.astype(str)
            elif op == "complex" and a.dtype.kind in "biufc":
                a = a + 1j
            elif op == "bool" and a.dtype.kind in "biufc":
                a = a > 0
            elif op == "empty":
                a = np.zeros((0,))
            elif op == "reverse_t" and a.ndim:
                a = a[::-1]
            elif op == "scalar":
                a = np.float64(3.0)
            elif op == "object":
                a = np.array([{"a": 1}], dtype=object)
            z[field] = a
        np.savez(folder / "traj0.npz", **z)
        _check(folder)


URDF = """<robot name="arm">
  <link name="base"/>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.3" rpy="1.5708 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="100" velocity="2"/>
  </joint>
  <link name="l1">
    <inertial><origin xyz="0.25 0 0"/><mass value="6"/>
      <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.15" iyz="0" izz="0.15"/></inertial>
  </link>
  <joint name="elbow" type="revolute">
    <parent link="l1"/><child link="l2"/>
    <origin xyz="0.5 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="50" velocity="2"/>
  </joint>
  <link name="l2">
    <inertial><origin xyz="0.2 0 0"/><mass value="3"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.06" iyz="0" izz="0.06"/></inertial>
  </link>
  <joint name="tool_joint" type="fixed"><parent link="l2"/><child link="tool"/><origin xyz="0.4 0 0"/></joint>
  <link name="tool"/>
</robot>
"""
TOKENS = re.compile(r'<[^>]+>|"[^"]*"')
BAD_TEXT = ['""', '"abc"', '"nan"', '"-1"', '"inf"', '"1 2"', '"0 0"', '"shoulder"', '"base"', '"l1"', '"1e400"',
            "", "<joint>", "<link/>", '<link name="l1"/>', "<mimic joint=\"shoulder\"/>"]


@SETTINGS
@given(st.lists(st.tuples(st.integers(0, 10**6), st.sampled_from(BAD_TEXT)), min_size=1, max_size=3),
       st.integers(0, 4000))
def test_mutated_urdf(edits, cut):
    text = URDF
    for k, new in edits:
        spans = [m.span() for m in TOKENS.finditer(text)]
        a, b = spans[k % len(spans)]
        text = text[:a] + new + text[b:]
    if cut < len(text):
        text = text[:cut]
    with _case_dir() as folder:
        (folder / "robot.urdf").write_text(text)
        cfg = yaml.safe_load((folder / "case.yaml").read_text())
        cfg["robot"] = "robot.urdf"
        (folder / "case.yaml").write_text(yaml.safe_dump(cfg))
        _check(folder)


# --- robot-YAML paths: a robot.yaml in the case names its URDF (urdf:) and the joints it keeps --------
SMALL = settings(SETTINGS, max_examples=200 if SLOW else 25)
PATHS = ["arm.urdf", "./arm.urdf", "sub/../arm.urdf", "sub/arm.urdf", "../outside.urdf", "../case/arm.urdf",
         "sub/../../outside.urdf", "OUTSIDE_ABS", "/etc/passwd", "/", ".", "", "~/arm.urdf", "arm.urdf\x00.txt",
         "a" * 300 + ".urdf", "x/" * 2000 + "arm.urdf", "link_out.urdf", "sub", "arm.URDF", "C:\\arm.urdf",
         "ärm.urdf", "arm.urdf ", "\\..\\outside.urdf"]
JOINTS = [None, ["shoulder"], ["shoulder", "elbow"], ["elbow", "elbow"], [], ["nope"], "shoulder", [1, 2],
          ["shoulder", "shoulder", "elbow"]]


@SMALL
@given(st.sampled_from(PATHS), st.text(max_size=12), st.sampled_from(JOINTS), st.booleans())
def test_robot_yaml_paths(path, junk, joints, add_junk):
    with _case_dir() as folder:
        (folder / "arm.urdf").write_text(URDF)
        (folder / "sub").mkdir()
        outside = folder.parent / "outside.urdf"
        outside.write_text(URDF)
        (folder / "link_out.urdf").symlink_to(outside)
        given_path = str(outside) if path == "OUTSIDE_ABS" else path + (junk if add_junk else "")
        robot = {"urdf": given_path}
        if joints is not None:
            robot["joints"] = joints
        (folder / "robot.yaml").write_text(yaml.safe_dump(robot, allow_unicode=True))
        if _check(folder) == "ok":
            # loaded: then the URDF it read lies inside the case folder, symbolic links resolved
            target = (folder / given_path).resolve()
            assert target.is_relative_to(folder.resolve()), f"read {target} from outside the case"
            assert joints is None or len(set(joints)) == len(joints)


# --- YAML aliases, merge keys and repeated keys in case.yaml and robot.yaml -----------------------------
def _alias_doc(fan, depth, where):
    """A YAML document whose key ``where`` holds ``fan ** depth`` strings through anchors."""
    lines = [f"_a0: &a0 [{', '.join(['x'] * fan)}]"]
    for i in range(1, depth):
        lines.append(f"_a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * fan)}]")
    lines.append(f"{where}: *a{depth - 1}")
    return "\n".join(lines) + "\n"


ALIAS_KIND = st.sampled_from(["bomb", "recursive", "duplicate", "merge"])


@SMALL
@given(ALIAS_KIND, st.integers(1, 12), st.integers(1, 9), st.sampled_from(["case", "robot"]),
       st.sampled_from(["datasets", "notes", "nominal_effects", "robot", "links", "gravity", "joint_names"]))
@example("bomb", 12, 9, "case", "datasets")  # 5e9 strings: the old loader hung here
@example("bomb", 10, 6, "robot", "links")
@example("recursive", 1, 1, "robot", "links")
@example("duplicate", 1, 1, "case", "notes")
def test_yaml_aliases(kind, fan, depth, target, key):
    import time

    with _case_dir() as folder:
        file = folder / ("case.yaml" if target == "case" else "robot.yaml")
        good = file.read_text()
        if kind == "bomb":
            text = good + _alias_doc(fan, depth, "_bomb")
            text = text.replace(f"\n{key}:", "\n_replaced:", 1) + f"{key}: *a{depth - 1}\n"
        elif kind == "recursive":
            text = good + f"_r: &r [1, *r]\n{key}: *r\n"
        elif kind == "duplicate":
            text = good + f"{key}: []\n{key}: {{}}\n"
        else:  # a merge key overriding a value is ordinary YAML, and still validated
            text = good + f"_base: &b {{x: {fan}}}\n{key}: {{<<: *b, x: {depth}}}\n"
        file.write_text(text)
        t = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                load_case(folder)
        except jflex.JFlexError as exc:
            msg = str(exc)
            assert file.name in msg, msg
            if kind == "bomb" and fan ** depth > MAX_YAML_NODES:
                assert "aliases" in msg, msg
            assert FIELD.search(msg) or re.search(r"aliases|recursive alias|duplicate key", msg), msg
            if kind == "recursive":
                assert "recursive alias" in msg, msg
        # a bomb is refused before anything walks it: seconds, even on two busy cores, never minutes
        assert time.perf_counter() - t < 30, (kind, fan, depth)
