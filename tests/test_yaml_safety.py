"""The one YAML loader jflex reads every config, robot file and case.yaml with refuses, quickly and
by name, what PyYAML's safe loader accepts silently: an alias bomb (1 KB standing for 1e9 nodes), a
recursive alias, a key given twice, nesting past the interpreter's recursion limit."""

from __future__ import annotations

import pathlib
import re
import sys
import time

import pytest

import jflex
from jflex._runs import MAX_YAML_NODES

ROOT = pathlib.Path(__file__).resolve().parent.parent


def _bomb(levels=9, fan=10) -> str:
    names = [f"l{i}" for i in range(levels + 1)]
    lines = [f"{names[0]}: &{names[0]} [" + ", ".join(["lol"] * fan) + "]"]
    for prev, cur in zip(names, names[1:]):
        lines.append(f"{cur}: &{cur} [" + ", ".join([f"*{prev}"] * fan) + "]")
    return "\n".join(lines) + "\n"


def test_alias_bomb_refused_quickly(tmp_path):
    text = _bomb()  # 10^10 strings once expanded
    assert len(text) < 1024
    f = tmp_path / "bomb.yaml"
    f.write_text(text)
    t = time.perf_counter()
    with pytest.raises(jflex.ConfigError, match=r"bomb\.yaml: .*expands to more than .* nodes through its aliases"):
        jflex.load_yaml(f)
    # not a timing claim: a hang (the old behaviour) would take minutes; this bounds it loosely
    assert time.perf_counter() - t < 10


def test_alias_bomb_in_a_robot_file_refused(tmp_path):
    (tmp_path / "robot.yaml").write_text(_bomb())
    with pytest.raises(jflex.ConfigError, match="aliases"):
        jflex.load_robot(tmp_path / "robot.yaml")


def test_aliases_below_the_limit_still_read(tmp_path):
    # anchors are ordinary YAML: a shared block used a few times reads as written out
    f = tmp_path / "ok.yaml"
    f.write_text("base: &b {mass: 1.0, com: [0, 0, 0.1]}\nlinks: [*b, *b]\nmore: {<<: *b, mass: 2.0}\n")
    got = jflex.load_yaml(f)
    assert got["links"] == [{"mass": 1.0, "com": [0, 0, 0.1]}] * 2
    assert got["more"] == {"mass": 2.0, "com": [0, 0, 0.1]}
    # a document just under the limit (counted with every alias written out) is read
    n = int(MAX_YAML_NODES ** 0.5) // 2
    f.write_text(f"row: &r [{', '.join(['0'] * n)}]\ntable: [{', '.join(['*r'] * n)}]\n")
    assert len(jflex.load_yaml(f)["table"]) == n


def test_recursive_alias_refused(tmp_path):
    f = tmp_path / "rec.yaml"
    f.write_text("a: &a [1, *a]\n")
    with pytest.raises(jflex.ConfigError, match="recursive alias at line 1"):
        jflex.load_yaml(f)


@pytest.mark.parametrize("text,key,line,first", [
    ("a: 1\nb: 2\na: 3\n", "a", 3, 1),
    ("robot:\n  mass: 1\n  com: [0, 0, 0]\n  mass: 2\n", "mass", 4, 2),
    ("- {x: 1, x: 2}\n", "x", 1, 1),
])
def test_duplicate_key_refused_with_key_and_line(tmp_path, text, key, line, first):
    f = tmp_path / "dup.yaml"
    f.write_text(text)
    with pytest.raises(jflex.ConfigError) as exc:
        jflex.load_yaml(f)
    msg = str(exc.value)
    assert f"duplicate key '{key}' at line {line} (first given at line {first})" in msg and "dup.yaml" in msg, msg


def test_deep_nesting_refused(tmp_path):
    f = tmp_path / "deep.yaml"
    f.write_text("a: " + "[" * 400 + "]" * 400 + "\n")
    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(300)  # PyYAML's parser is quadratic in depth: hit the limit at a small depth
    try:
        with pytest.raises(jflex.ConfigError, match="nested too deeply"):
            jflex.load_yaml(f)
    finally:
        sys.setrecursionlimit(limit)


def test_every_shipped_yaml_reads():
    files = [*ROOT.glob("configs/**/*.yaml"), *ROOT.glob("jflex/data/**/*.yaml")]
    assert files
    for f in files:
        assert isinstance(jflex.load_yaml(f), dict), f


def test_jflex_reads_yaml_only_through_load_yaml():
    # one loader, so its limits hold everywhere: no other yaml.load / safe_load in the library
    # or the experiment scripts (writing YAML with yaml.safe_dump is fine)
    pattern = re.compile(r"yaml\.(safe_)?load(_all)?\(|yaml\.(full_|unsafe_)?load\(")
    offenders = []
    for f in [*ROOT.glob("jflex/**/*.py"), *ROOT.glob("experiments/*.py")]:
        for i, line in enumerate(f.read_text(encoding="utf-8").splitlines(), 1):
            if pattern.search(line) and not (f.name == "_runs.py" and "Loader=_Loader" in line):
                offenders.append(f"{f.relative_to(ROOT)}:{i}: {line.strip()}")
    assert not offenders, offenders
