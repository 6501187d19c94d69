"""`python benchmarks/bench_gap.py`: its --help says what each --size runs (checked against the
plan), `jflex` itself has no bench subcommand (the wheel lacks the generators), and without mujoco
installed the MuJoCo family is skipped with one line instead of a ModuleNotFoundError."""

import collections
import importlib.util
import pathlib
import re
import sys

import pytest

from jflex_family import bench as _bench

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _bench_script():
    spec = importlib.util.spec_from_file_location("_bench_gap_script", ROOT / "benchmarks" / "bench_gap.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _counts(size):
    plan = _bench.plan(size)
    kinds = collections.Counter(
        (c["family"], "null" if not c["truths"] else "pair" if len(c["truths"]) > 1 else "one") for c in plan
    )
    return len(plan), kinds


def test_help_states_what_each_size_runs():
    n_full, full = _counts("full")
    n_small, small = _counts("small")
    script = _bench_script()
    text = " ".join(script.SIZES.split())
    assert f"--size full (the default) runs {n_full} cases" in text
    assert f"8 torque-side effects on 3 robots (arm3, planar2, arm4: {full['torque', 'one']})" in text
    assert f"{full['mujoco', 'one']} MuJoCo-simulated" in text and f"{full['torque', 'pair']} effect pairs" in text
    assert f"{full['frf', 'one']} FRF-side effects" in text
    nulls = full["torque", "null"] + full["frf", "null"]
    assert f"{nulls} null cases ({full['torque', 'null']} torque, {full['frf', 'null']} FRF)" in text
    assert f"--size small runs {n_small}: the {small['torque', 'one']} torque-side effects, the {small['mujoco', 'one']} MuJoCo" in text
    assert f"{small['torque', 'pair']} pair and {small['frf', 'one']} FRF-side effect on arm3, and {small['torque', 'null']} null" in text
    helptext = script.build_parser().format_help()
    assert re.search(rf"full \(the default\): {n_full} cases; small: {n_small}", " ".join(helptext.split()))


def test_jflex_has_no_bench_subcommand():
    from jflex.cli import build_parser

    sub = next(a for a in build_parser()._subparsers._group_actions if a.choices)
    assert "diagnose" in sub.choices and "gap-bench" not in sub.choices
    with pytest.raises(SystemExit):
        build_parser().parse_args(["gap-bench"])


def test_without_mujoco_the_family_is_skipped_in_one_line(monkeypatch):
    monkeypatch.setitem(sys.modules, "mujoco", None)  # import mujoco -> ImportError, as when not installed
    lines = []
    specs = _bench.runnable(_bench.plan("small"), lines.append)
    n_mujoco = sum(c["family"] == "mujoco" for c in _bench.plan("small"))
    assert n_mujoco > 0 and len(specs) == len(_bench.plan("small")) - n_mujoco
    assert all(c["family"] != "mujoco" for c in specs)
    assert len(lines) == 1 and "MuJoCo family skipped" in lines[0] and "mujoco is not installed" in lines[0]
    # ids stay those of the full plan, so a later run with mujoco resumes the same folders
    assert {c["id"] for c in specs} <= {c["id"] for c in _bench.plan("small")}
