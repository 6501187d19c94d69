"""The library's structure, read off its import statements (docs/architecture.md draws it).

- Layers: a module imports only from its own layer or those below it (``LAYERS``, bottom first).
- ``jflex.data`` imports nothing of jflex but its errors: readers and conditioning serve every
  analysis and know none of them.
- No import cycle between the modules of ``jflex.gap`` (a lazy import or one under
  ``TYPE_CHECKING`` counts: it is still a walk back into a room already left).
- In ``jflex.data`` and ``jflex.gap`` every file is at most 600 lines and every function at most
  100 lines.
- Each effect's name is written as a string literal once in the library (in its registry)."""

from __future__ import annotations

import ast
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent
LIB = ROOT / "jflex"

# bottom first; a top-level module or a package belongs to exactly one layer
LAYERS = [
    ("foundation", {"jflex._errors", "jflex._paths", "jflex._schema", "jflex._inputs", "jflex._trig",
                    "jflex._fingerprint", "jflex._progress", "jflex._allocator", "jflex._compile_clock",
                    "jflex._fold", "jflex._beam", "jflex._lagrangian"}),
    ("data", {"jflex.data"}),
    ("rigid core", {"jflex._robot", "jflex._scalar", "jflex._spatial", "jflex._checks", "jflex._coupling",
                    "jflex._tree", "jflex._dynamics", "jflex._derivatives", "jflex._dh", "jflex._urdf",
                    "jflex._compiled", "jflex._program_cache", "jflex._sweep", "jflex._compilation_cache",
                    "jflex._runs", "jflex._config"}),
    ("model", {"jflex.effects", "jflex._model"}),
    ("analyses", {"jflex.linear", "jflex._simulate", "jflex.identify", "jflex.fem"}),
    ("diagnosis", {"jflex.gap"}),
    ("front", {"jflex", "jflex.cli", "jflex._demo_config"}),
]
PACKAGES = ("data", "effects", "linear", "identify", "gap", "fem")


def _modules():
    """(path, dotted module name, is a package's __init__) of every library file."""
    out = []
    for p in sorted(LIB.rglob("*.py")):
        parts = list(p.relative_to(ROOT).with_suffix("").parts)
        init = parts[-1] == "__init__"
        out.append((p, ".".join(parts[:-1] if init else parts), init))
    return out


MODULES = _modules()
NAMES = {m for _, m, _ in MODULES}


def _imports(path, mod, init):
    """Every jflex module a file imports (any depth: lazy and TYPE_CHECKING imports included)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = mod.split(".") if init else mod.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "jflex":
                continue
            for a in node.names:
                out.add(f"{target}.{a.name}" if f"{target}.{a.name}" in NAMES else target)
        elif isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.split(".")[0] == "jflex"}
    return out


GRAPH = {mod: _imports(p, mod, init) for p, mod, init in MODULES}


def _unit(mod):
    parts = mod.split(".")
    return ".".join(parts[:2]) if len(parts) >= 2 and parts[1] in PACKAGES else mod


def _layer(unit):
    for i, (_, units) in enumerate(LAYERS):
        if unit in units:
            return i
    return None


def test_every_module_has_a_layer():
    missing = sorted({_unit(m) for m in NAMES if _layer(_unit(m)) is None})
    assert not missing, f"modules with no layer in tests/test_architecture.py LAYERS: {missing}"


def test_no_import_runs_up_a_layer():
    up = []
    for mod, targets in GRAPH.items():
        for t in targets:
            if t == "jflex" and mod != "jflex":
                continue  # `from jflex import __version__`-style reads of the package's own metadata
            a, b = _layer(_unit(mod)), _layer(_unit(t))
            if a is not None and b is not None and b > a:
                up.append(f"{mod} ({LAYERS[a][0]}) imports {t} ({LAYERS[b][0]})")
    assert not up, "\n".join(sorted(up))


def test_data_imports_only_the_errors():
    bad = sorted(f"{m} -> {t}" for m, ts in GRAPH.items() if _unit(m) == "jflex.data"
                 for t in ts if _unit(t) != "jflex.data" and t != "jflex._errors")
    assert not bad, bad


def test_no_cycle_inside_gap():
    g = {m: {t for t in ts if t in NAMES and t.startswith("jflex.gap.") and not t.endswith("__init__")}
         for m, ts in GRAPH.items() if m.startswith("jflex.gap.")}
    seen, stack, cycles = {}, [], []

    def visit(v):
        seen[v] = "open"
        stack.append(v)
        for w in sorted(g.get(v, ())):
            if seen.get(w) == "open":
                cycles.append(stack[stack.index(w):] + [w])
            elif w not in seen:
                visit(w)
        stack.pop()
        seen[v] = "done"

    for v in sorted(g):
        if v not in seen:
            visit(v)
    assert not cycles, "\n".join(" -> ".join(c) for c in cycles)


@pytest.mark.parametrize("package", ["data", "gap"])
def test_files_and_functions_are_short(package):
    long = []
    for p in sorted((LIB / package).rglob("*.py")):
        text = p.read_text()
        if len(text.splitlines()) > 600:
            long.append(f"{p.relative_to(ROOT)}: {len(text.splitlines())} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > 100:
                    long.append(f"{p.relative_to(ROOT)}:{node.lineno} {node.name}: {n} lines")
    assert not long, "\n".join(long)


# The same word as a field of another thing, not the effect's name: (file, word) -> what it names.
NOT_THE_EFFECT = {
    ("jflex/effects/_flexible_joint.py", "rotor_inertia"): "FlexibleJoints' field: the rotor behind a joint's spring",
    ("jflex/gap/response/_simulated.py", "rotor_inertia"): "the path of that FlexibleJoints field, fitted",
    ("jflex/data/_csv.py", "torque_offset"): "a case's data field: a constant subtracted from a torque column",
    ("jflex/gap/case/_schema.py", "torque_offset"): "the same case data field, validated",
}


def test_each_effect_name_is_written_once():
    from jflex.gap import EFFECT_NAMES

    where = {name: [] for name in EFFECT_NAMES}
    for p, _, _ in MODULES:
        rel = str(p.relative_to(ROOT))
        for node in ast.walk(ast.parse(p.read_text())):
            if (isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in where
                    and (rel, node.value) not in NOT_THE_EFFECT):
                where[node.value].append(f"{p.relative_to(ROOT)}:{node.lineno}")
    repeated = {k: v for k, v in where.items() if len(v) != 1}
    assert not repeated, repeated
